"""DGSE: deep probabilistic gas source estimation and active search for indoor robots.

Subpackages, one per domain concept: ``world`` (layouts, grids, cases),
``physics`` (RANS flow, transport, filaments, OpenFOAM), ``sensing``,
``data``, ``models``, ``training``, ``estimators`` (the one belief
interface), ``mapping`` and ``localization`` (the field's baselines),
``search``, ``evaluation``, ``bench`` and ``viz``; ``cli`` is the ``dgse``
command.
"""


def __getattr__(name: str) -> str:
    # the version is looked up on first use: most commands never print it, and importing
    # importlib.metadata added to every process's start-up (`python -X importtime -c "import dgse"`)
    if name != "__version__":
        raise AttributeError(f"module 'dgse' has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    global __version__
    try:
        __version__ = version("dgse")
    except PackageNotFoundError:  # running from a source tree that is not installed
        __version__ = "0+unknown"
    return __version__
