"""DGSE: deep probabilistic gas source estimation and active search for indoor robots.

Subpackages, one per domain concept: ``world`` (layouts, grids, cases),
``physics`` (RANS flow, transport, filaments, OpenFOAM), ``sensing``,
``data``, ``models``, ``training``, ``estimators`` (the one belief
interface), ``mapping`` and ``localization`` (the field's baselines),
``search``, ``evaluation``, ``bench`` and ``viz``; ``cli`` is the ``dgse``
command.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("dgse")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"
