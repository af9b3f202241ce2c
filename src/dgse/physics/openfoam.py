"""OpenFOAM v1912 backend: spec section 4 solved with blockMesh, simpleFoam and scalarTransport.

The engine writes one OpenFOAM case per layout into a temporary directory and
runs, serially (or with ``n_procs > 1`` the flow in parallel):

1. ``blockMesh``: the ``W x H`` m rectangle, one hexahedron per grid cell,
   one cell (``slab_depth`` = 1 m) thick in z with ``empty`` front and back;
   every side face starts in the ``walls`` patch.
2. ``topoSet`` + ``createPatch``: one ``inlet<n>``/``outlet<n>`` patch per
   :class:`~dgse.world.layout.Opening` of ``layout.inlets``/``layout.outlets``
   (the boundary faces of the cells :meth:`Opening.cells` names).
3. ``topoSet`` + ``subsetMesh``: the solid cells are removed; the faces this
   exposes join the ``walls`` patch.
4. ``simpleFoam``: standard k-epsilon with standard wall functions, SIMPLEC,
   relaxation 0.9 (U) and 0.8 (k, epsilon), bounded second-order
   ``linearUpwind`` convection on cell-limited gradients, residual target
   1e-5 for every equation.
5. per source, ``simpleFoam -postProcess`` on the frozen flow with a
   ``scalarTransport`` function object (``D = D_m + nu_t / Sc_t``,
   conservative unbounded ``linearUpwind``, a ``scalarSemiImplicitSource`` of
   ``q / (dx dy h)`` g/(m^3 s) in the source cell) and a ``writeObjects``
   function object (without it the field is never written).

The results are read back onto the layout's ``(H, W)`` grid (0 in solid
cells), the gas converted from g/m^3 to ppm, and the scalar flux out of the
outlets compared with the release rate.

The settings reproduce the reference cases of ``shared/reference-cases``
(velocity relative L2 error 1e-5 to 1e-4, RMSE of ``log(1 + ppm)`` below
0.011, the same outlet flux ratios).  They are sensitive: only the
convection terms use the cell-limited gradient (``grad(U)`` of the
``dev2`` stress term stays ``Gauss linear``; limiting it too moves the wind
by 4-6 %), and the gas equation is not under-relaxed.

Importing this module is cheap; :meth:`OpenFOAMEngine.unavailable` looks for the
executables (:func:`find_openfoam`, ``shutil.which``) and says why the engine cannot
run where they are missing.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dgse.errors import ConvergenceError, DGSEError, InputDataError, UnsupportedError
from dgse.physics.constants import DEFAULT_PHYSICS, Physics
from dgse.physics.engines import FlowField, Solution, Source, check_mass_balance
from dgse.world.generate import ventilated_cells
from dgse.world.layout import INWARD_NORMAL, Layout, Opening

__all__ = [
    "ENGINE_NAME",
    "INSTALL_HINT",
    "REQUIRED_UTILITIES",
    "OpenFOAMEngine",
    "OpenFOAMError",
    "OpenFOAMTimeoutError",
    "find_openfoam",
    "openfoam_environment",
    "unavailable_reason",
]

ENGINE_NAME = "openfoam"
#: Executables the backend runs; all must sit in one directory.
REQUIRED_UTILITIES = ("blockMesh", "topoSet", "createPatch", "subsetMesh", "simpleFoam")
INSTALL_HINT = "install the Debian package openfoam (apt-get install openfoam)"
#: Environment variable naming the directory of the OpenFOAM executables (optional).
BIN_DIR_ENV = "DGSE_OPENFOAM_BIN"
#: Where Debian's package keeps ``etc/controlDict`` (its binaries need ``WM_PROJECT_DIR``).
DEBIAN_PROJECT_DIR = "/usr/share/openfoam"
#: Searched after ``$DGSE_OPENFOAM_BIN``, ``$PATH`` and ``$FOAM_APPBIN``.
FALLBACK_BIN_DIRS: tuple[str, ...] = ("/usr/bin",)

#: Residual target of every flow equation (initial residual, as OpenFOAM's residualControl).
RESIDUAL_TARGET = 1e-5
#: Under-relaxation of the momentum equation and of k and epsilon (the gas is not relaxed).
RELAX_U = 0.9
RELAX_OTHER = 0.8
#: A gas solve whose last initial residual is above this is flagged ``converged: False``.
GAS_RESIDUAL_OK = 1e-6
_FOAM_VERSION_BANNER = "v1912"


class OpenFOAMError(DGSEError):
    """An OpenFOAM utility failed; the message names it and quotes the end of its log."""

    def __init__(self, utility: str, message: str, log_tail: str = "", log_path: str = "") -> None:
        text = f"OpenFOAM {utility} failed: {message}"
        if log_path:
            text += f" (log: {log_path})"
        if log_tail:
            text += "\n--- last lines of the log ---\n" + log_tail
        super().__init__(text)
        self.utility = utility
        self.log_tail = log_tail
        self.log_path = log_path


class OpenFOAMTimeoutError(OpenFOAMError):
    """An OpenFOAM utility ran past the engine's ``timeout``."""


# --------------------------------------------------------------------------------------
# finding the installation
# --------------------------------------------------------------------------------------
def find_openfoam() -> str | None:
    """The directory holding all :data:`REQUIRED_UTILITIES`, or ``None``.

    Looks, in order, in ``$DGSE_OPENFOAM_BIN``, on ``$PATH``, in
    ``$FOAM_APPBIN`` (a sourced OpenFOAM ``etc/bashrc``) and in
    :data:`FALLBACK_BIN_DIRS` (Debian installs the binaries in ``/usr/bin``).
    Only ``shutil.which`` is called: no subprocess.
    """
    searches: list[str | None] = []
    if os.environ.get(BIN_DIR_ENV):
        searches.append(os.environ[BIN_DIR_ENV])
    searches.append(None)  # $PATH
    if os.environ.get("FOAM_APPBIN"):
        searches.append(os.environ["FOAM_APPBIN"])
    searches.extend(FALLBACK_BIN_DIRS)
    for path in searches:
        exe = shutil.which("simpleFoam", path=path)
        if not exe:
            continue
        bin_dir = os.path.dirname(os.path.abspath(exe))
        if all(shutil.which(u, path=bin_dir) for u in REQUIRED_UTILITIES):
            return bin_dir
    return None


def _project_dir(bin_dir: str) -> str | None:
    """A ``WM_PROJECT_DIR`` that holds ``etc/controlDict`` for the binaries in ``bin_dir``."""
    env_dir = os.environ.get("WM_PROJECT_DIR")
    if env_dir and os.path.isfile(os.path.join(env_dir, "etc", "controlDict")):
        return env_dir
    parent = os.path.dirname(bin_dir)
    for cand in (
        os.path.join(parent, "share", "openfoam"),  # Debian: /usr/bin -> /usr/share/openfoam
        DEBIAN_PROJECT_DIR,
        parent,  # OpenCFD layout: <root>/platforms/<arch>/bin -> ...; <root>/bin
        os.path.dirname(os.path.dirname(parent)),
    ):
        if os.path.isfile(os.path.join(cand, "etc", "controlDict")):
            return cand
    return env_dir or None


def openfoam_environment(bin_dir: str) -> dict[str, str]:
    """The environment the utilities run in: ``PATH`` first, ``WM_PROJECT_DIR`` set.

    Debian's binaries stop with "Could not find mandatory etc entry 'controlDict'"
    unless ``WM_PROJECT_DIR`` points at ``/usr/share/openfoam``.
    """
    env = dict(os.environ)
    project = _project_dir(bin_dir)
    if project:
        env["WM_PROJECT_DIR"] = project
    env["PATH"] = bin_dir + os.pathsep + env.get("PATH", "")
    env.setdefault("OMP_NUM_THREADS", "1")
    env.setdefault("FOAM_SIGFPE", "true")  # stop on floating-point errors (a diverging run)
    # mpirun of the Debian openmpi refuses root unless told (only used with n_procs > 1)
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    return env


def unavailable_reason() -> str:
    """Why the engine cannot run here (shown by ``get_engine("openfoam")``)."""
    others = ", ".join(u for u in REQUIRED_UTILITIES if u != "simpleFoam")
    return (
        f"simpleFoam (with {others}) not found on PATH; {INSTALL_HINT}, "
        f"or set {BIN_DIR_ENV} to the directory of the OpenFOAM v1912 executables"
    )


# --------------------------------------------------------------------------------------
# OpenFOAM dictionaries
# --------------------------------------------------------------------------------------
def _num(x: float) -> str:
    """A float as OpenFOAM reads it back exactly."""
    return repr(float(x))


def _vec(v: Sequence[float]) -> str:
    return "(" + " ".join(_num(c) for c in v) + ")"


def _foam_file(cls: str, obj: str, body: str, location: str | None = None) -> str:
    loc = f'    location    "{location}";\n' if location else ""
    return (
        "/*--------------------------------*- C++ -*----------------------------------*\\\n"
        "  Written by dgse.physics.openfoam for OpenFOAM v1912\n"
        "\\*---------------------------------------------------------------------------*/\n"
        "FoamFile\n{\n    version     2.0;\n    format      ascii;\n"
        f"    class       {cls};\n{loc}    object      {obj};\n}}\n\n{body}\n"
    )


def _write(case: Path, rel: str, cls: str, body: str) -> None:
    path = case / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    location = str(Path(rel).parent) if str(Path(rel).parent) != "." else None
    path.write_text(_foam_file(cls, Path(rel).name, body, location))


@dataclass(frozen=True)
class _Patch:
    """An inlet or outlet patch: its name, opening and grid cells (rows, cols)."""

    name: str
    opening: Opening
    rows: np.ndarray
    cols: np.ndarray


def _block_mesh_dict(layout: Layout, depth: float) -> str:
    g = layout.grid
    lx, ly = g.width * g.resolution, g.height * g.resolution
    pts = [
        (0, 0, 0),
        (lx, 0, 0),
        (lx, ly, 0),
        (0, ly, 0),
        (0, 0, depth),
        (lx, 0, depth),
        (lx, ly, depth),
        (0, ly, depth),
    ]
    vertices = "\n".join("    " + _vec(p) for p in pts)
    return f"""convertToMeters 1;

vertices
(
{vertices}
);

blocks
(
    hex (0 1 2 3 4 5 6 7) ({g.width} {g.height} 1) simpleGrading (1 1 1)
);

edges ();

boundary
(
    walls
    {{
        type wall;
        faces
        (
            (3 7 6 2)
            (0 4 7 3)
            (2 6 5 1)
            (1 5 4 0)
        );
    }}
    frontAndBack
    {{
        type empty;
        faces
        (
            (0 3 2 1)
            (4 5 6 7)
        );
    }}
);

mergePatchPairs ();
"""


def _opening_box(layout: Layout, patch: _Patch, depth: float) -> tuple[tuple, tuple]:
    """A box containing exactly the boundary-face centres of the patch's cells."""
    g = layout.grid
    r = g.resolution
    lx, ly = g.width * r, g.height * r
    side = patch.opening.side
    along = patch.cols if side in ("south", "north") else patch.rows
    a0 = float(along.min()) * r + 0.25 * r
    a1 = float(along.max() + 1) * r - 0.25 * r
    z0, z1 = -0.25 * depth, 1.25 * depth
    e = 0.25 * r
    if side == "west":
        return (-e, a0, z0), (e, a1, z1)
    if side == "east":
        return (lx - e, a0, z0), (lx + e, a1, z1)
    if side == "south":
        return (a0, -e, z0), (a1, e, z1)
    return (a0, ly - e, z0), (a1, ly + e, z1)


def _labels(values: np.ndarray, per_line: int = 20) -> str:
    vals = [str(int(v)) for v in values]
    lines = [" ".join(vals[i : i + per_line]) for i in range(0, len(vals), per_line)]
    return "(\n" + "\n".join("            " + ln for ln in lines) + "\n        )"


def _topo_set_patches(layout: Layout, patches: Sequence[_Patch], depth: float) -> str:
    actions = []
    for p in patches:
        lo, hi = _opening_box(layout, p, depth)
        actions.append(
            f"""    {{
        name    {p.name}Faces;
        type    faceSet;
        action  new;
        source  boxToFace;
        sourceInfo
        {{
            box {_vec(lo)} {_vec(hi)};
        }}
    }}"""
        )
    return "actions\n(\n" + "\n".join(actions) + "\n);\n"


def _topo_set_fluid(free_labels: np.ndarray) -> str:
    return f"""actions
(
    {{
        name    fluid;
        type    cellSet;
        action  new;
        source  labelToCell;
        sourceInfo
        {{
            value {_labels(free_labels)};
        }}
    }}
);
"""


def _create_patch_dict(patches: Sequence[_Patch]) -> str:
    items = "\n".join(
        f"""    {{
        name {p.name};
        patchInfo
        {{
            type patch;
        }}
        constructFrom set;
        set {p.name}Faces;
    }}"""
        for p in patches
    )
    return f"pointSync false;\n\npatches\n(\n{items}\n);\n"


def _boundary_block(entries: dict[str, str]) -> str:
    body = "\n".join(f"    {name}\n    {{\n{text}    }}" for name, text in entries.items())
    return "boundaryField\n{\n" + body + "\n}\n"


def _field(dims: str, internal: str, boundary: dict[str, str]) -> str:
    return f"dimensions      {dims};\n\ninternalField   {internal};\n\n" + _boundary_block(boundary)


def _entry(**kv: str) -> str:
    return "".join(f"        {k:<15} {v};\n" for k, v in kv.items())


@dataclass(frozen=True)
class _InletState:
    velocity: tuple[float, float, float]
    k: float
    epsilon: float


def _flow_fields(
    inlets: Sequence[_Patch],
    outlets: Sequence[_Patch],
    states: Sequence[_InletState],
    phys: Physics,
) -> dict[str, tuple[str, str]]:
    """``{file: (class, body)}`` of the initial fields U, p, k, epsilon, nut."""
    k0 = float(np.mean([s.k for s in states]))
    e0 = float(np.mean([s.epsilon for s in states]))
    empty = _entry(type="empty")
    wf_coeffs = {"Cmu": _num(phys.C_mu), "kappa": _num(phys.kappa), "E": _num(phys.E)}

    def bc(walls: str, inlet: dict[str, str], outlet: str) -> dict[str, str]:
        d = {"walls": walls, "frontAndBack": empty}
        d.update(inlet)
        d.update({p.name: outlet for p in outlets})
        return d

    u_in = {
        p.name: _entry(type="fixedValue", value=f"uniform {_vec(s.velocity)}")
        for p, s in zip(inlets, states, strict=True)
    }

    def turbulence(dims: str, wall_function: str, value: float, at_inlets: list[float]) -> tuple[str, str]:
        """A k or epsilon field: ``value`` inside, at the wall function and at the outlets
        (``inletOutlet``), ``at_inlets`` fixed at the inlets."""
        uniform = f"uniform {_num(value)}"
        inlet = {
            p.name: _entry(type="fixedValue", value=f"uniform {_num(x)}")
            for p, x in zip(inlets, at_inlets, strict=True)
        }
        walls = _entry(type=wall_function, value=uniform)
        outlet = _entry(type="inletOutlet", inletValue=uniform, value=uniform)
        return "volScalarField", _field(dims, uniform, bc(walls, inlet, outlet))

    zg = _entry(type="zeroGradient")
    calc0 = _entry(type="calculated", value="uniform 0")
    return {
        "U": (
            "volVectorField",
            _field("[0 1 -1 0 0 0 0]", "uniform (0 0 0)", bc(_entry(type="noSlip"), u_in, zg)),
        ),
        "p": (
            "volScalarField",
            _field(
                "[0 2 -2 0 0 0 0]",
                "uniform 0",
                bc(zg, {p.name: zg for p in inlets}, _entry(type="fixedValue", value="uniform 0")),
            ),
        ),
        "k": turbulence("[0 2 -2 0 0 0 0]", "kqRWallFunction", k0, [s.k for s in states]),
        "epsilon": turbulence("[0 2 -3 0 0 0 0]", "epsilonWallFunction", e0, [s.epsilon for s in states]),
        "nut": (
            "volScalarField",
            _field(
                "[0 2 -1 0 0 0 0]",
                "uniform 0",
                bc(
                    _entry(type="nutkWallFunction", **wf_coeffs, value="uniform 0"),
                    {p.name: calc0 for p in inlets},
                    calc0,
                ),
            ),
        ),
    }


def _gas_field(inlets: Sequence[_Patch], outlets: Sequence[_Patch]) -> str:
    zg = _entry(type="zeroGradient")
    bc = {"walls": zg, "frontAndBack": _entry(type="empty")}
    bc.update({p.name: _entry(type="fixedValue", value="uniform 0") for p in inlets})
    bc.update({p.name: zg for p in outlets})
    return _field("[1 -3 0 0 0 0 0]", "uniform 0", bc)


def _control_dict(end_iteration: int, functions: str = "") -> str:
    return f"""application     simpleFoam;
startFrom       latestTime;
startTime       0;
stopAt          endTime;
endTime         {end_iteration};
deltaT          1;
writeControl    timeStep;
writeInterval   {end_iteration};
purgeWrite      0;
writeFormat     ascii;
writePrecision  14;
writeCompression off;
timeFormat      general;
timePrecision   8;
runTimeModifiable false;

functions
{{
{functions}}}
"""


def _fv_schemes(gas_fields: Sequence[str]) -> str:
    gas = "".join(f"    div(phi,{f}) Gauss linearUpwind limited;\n" for f in gas_fields)
    return f"""ddtSchemes
{{
    default         steadyState;
}}

gradSchemes
{{
    default         Gauss linear;
    limited         cellLimited Gauss linear 1;
}}

divSchemes
{{
    default         none;
    div(phi,U)      bounded Gauss linearUpwind limited;
    div(phi,k)      bounded Gauss linearUpwind limited;
    div(phi,epsilon) bounded Gauss linearUpwind limited;
{gas}    div((nuEff*dev2(T(grad(U))))) Gauss linear;
}}

laplacianSchemes
{{
    default         Gauss linear corrected;
}}

interpolationSchemes
{{
    default         linear;
}}

snGradSchemes
{{
    default         corrected;
}}
"""


def _fv_solution() -> str:
    return f"""solvers
{{
    p
    {{
        solver          GAMG;
        tolerance       1e-06;
        relTol          0.1;
        smoother        GaussSeidel;
    }}

    "(U|k|epsilon)"
    {{
        solver          smoothSolver;
        smoother        symGaussSeidel;
        tolerance       1e-08;
        relTol          0.1;
    }}

    "gas.*"
    {{
        solver          PBiCGStab;
        preconditioner  DILU;
        tolerance       1e-14;
        relTol          0.01;
    }}
}}

SIMPLE
{{
    nNonOrthogonalCorrectors 0;
    consistent      yes;

    residualControl
    {{
        p               {RESIDUAL_TARGET:g};
        U               {RESIDUAL_TARGET:g};
        "(k|epsilon)"   {RESIDUAL_TARGET:g};
    }}
}}

relaxationFactors
{{
    equations
    {{
        U               {RELAX_U};
        "(k|epsilon)"   {RELAX_OTHER};
    }}
}}
"""


def _transport_properties(phys: Physics) -> str:
    return f"transportModel  Newtonian;\n\nnu              {_num(phys.nu)};\n"


def _turbulence_properties(phys: Physics) -> str:
    return f"""simulationType  RAS;

RAS
{{
    RASModel        kEpsilon;
    turbulence      on;
    printCoeffs     on;

    kEpsilonCoeffs
    {{
        Cmu             {_num(phys.C_mu)};
        C1              {_num(phys.C_1)};
        C2              {_num(phys.C_2)};
        C3              0;
        sigmak          {_num(phys.sigma_k)};
        sigmaEps        {_num(phys.sigma_eps)};
    }}
}}
"""


def _gas_functions(
    field: str, point: tuple[float, float, float], rate: float, phys: Physics, n_corr: int
) -> str:
    """Function objects solving one source's gas field (g/m^3) and writing it."""
    return f"""    {field}
    {{
        type            scalarTransport;
        libs            ("libsolverFunctionObjects.so");
        field           {field};
        schemesField    {field};
        // D = alphaD*nu + alphaDt*nut = D_m + nut/Sc_t
        alphaD          {_num(phys.D_m / phys.nu)};
        alphaDt         {_num(1.0 / phys.Sc_t)};
        nCorr           {int(n_corr)};
        resetOnStartUp  false;
        fvOptions
        {{
            {field}Source
            {{
                type            scalarSemiImplicitSource;
                active          yes;
                selectionMode   points;
                points          ({_vec(point)});
                volumeMode      specific;
                injectionRateSuSp
                {{
                    {field}     ({_num(rate)} 0);
                }}
            }}
        }}
    }}
    write_{field}
    {{
        type            writeObjects;
        libs            ("libutilityFunctionObjects.so");
        objects         ({field});
        writeControl    timeStep;
        writeInterval   1;
    }}
"""


def _decompose_par_dict(n_procs: int, along_x: bool) -> str:
    # "simple" needs no third-party library (Debian's scotch method is a stub)
    n = f"({n_procs} 1 1)" if along_x else f"(1 {n_procs} 1)"
    return f"""numberOfSubdomains {n_procs};

method          simple;

coeffs
{{
    n               {n};
}}
"""


# --------------------------------------------------------------------------------------
# reading OpenFOAM ascii files
# --------------------------------------------------------------------------------------
def _strip_header(text: str) -> str:
    m = re.search(r"FoamFile\s*\{[^}]*\}", text)
    body = text[m.end() :] if m else text
    body = re.sub(r"/\*.*?\*/", " ", body, flags=re.S)
    return re.sub(r"//[^\n]*", " ", body)


def _parse_values(text: str, n: int | None, ncomp: int) -> np.ndarray:
    """The value that starts ``text`` (``uniform x`` or ``nonuniform List<T> ...``).

    Returns ``(n,)`` for scalars or ``(n, ncomp)`` for vectors; a ``uniform``
    value is broadcast to ``n`` entries.
    """
    s = text.lstrip()
    if s.startswith("uniform"):
        s = s[len("uniform") :].lstrip()
        if s.startswith("("):
            val = np.array(s[1 : s.index(")")].split(), dtype=float)
        else:
            val = np.array([float(s.split(";", 1)[0])])
        if n is None:
            raise DGSEError("uniform value where a sized list was expected")
        out = np.tile(val, (n, 1)) if ncomp > 1 else np.full(n, val[0])
        return out
    m = re.match(r"nonuniform\s+List<\w+>\s*(\d+)\s*([({])", s)
    if not m:
        m = re.match(r"(\d+)\s*([({])", s)  # plain list (mesh files)
    if not m:
        raise DGSEError(f"cannot parse OpenFOAM value starting {s[:60]!r}")
    size = int(m.group(1))
    rest = s[m.end() :]
    if m.group(2) == "{":  # compacted uniform list  N{value}
        inner = rest[: rest.index("}")].replace("(", " ").replace(")", " ")
        val = np.array(inner.split(), dtype=float)
        return np.tile(val, (size, 1)) if ncomp > 1 else np.full(size, val[0])
    count = size * ncomp
    tokens = rest.replace("(", " ").replace(")", " ").split(None, count)[:count]
    arr = np.array(tokens, dtype=float)
    if arr.size != count:
        raise DGSEError(f"OpenFOAM list of {size} entries is truncated")
    return arr.reshape(size, ncomp) if ncomp > 1 else arr


def _read_internal(path: Path, n_cells: int, ncomp: int = 1) -> np.ndarray:
    body = _strip_header(path.read_text())
    m = re.search(r"\binternalField\b", body)
    if not m:
        raise DGSEError(f"{path}: no internalField")
    return _parse_values(body[m.end() :], n_cells, ncomp)


def _read_patch_value(path: Path, patch: str, n_faces: int, ncomp: int = 1) -> np.ndarray:
    body = _strip_header(path.read_text())
    bf = body.find("boundaryField")
    m = re.compile(r"\n\s*" + re.escape(patch) + r"\s*\n\s*\{").search(body, bf)
    if not m:
        raise DGSEError(f"{path}: no patch {patch!r}")
    end = re.compile(r"\n\s*\}[ \t]*\n").search(body, m.end())
    block = body[m.end() : end.start() if end else len(body)]
    v = re.search(r"\bvalue\b", block)
    if not v:
        raise DGSEError(f"{path}: patch {patch!r} has no value")
    return _parse_values(block[v.end() :], n_faces, ncomp)


def _read_label_list(path: Path) -> np.ndarray:
    return _parse_values(_strip_header(path.read_text()), None, 1).astype(np.int64)


def _read_faces(path: Path) -> np.ndarray:
    """``(n_faces, 4)`` point labels of a mesh of quadrilateral faces (``polyMesh/faces``)."""
    body = _strip_header(path.read_text())
    m = re.match(r"\s*(\d+)\s*\(", body)
    if not m:
        raise DGSEError(f"{path}: cannot parse the face list")
    n = int(m.group(1))
    tokens = body[m.end() :].replace("(", " ").replace(")", " ").split(None, 5 * n)[: 5 * n]
    arr = np.array(tokens, dtype=np.int64).reshape(n, 5)
    if not (arr[:, 0] == 4).all():
        raise DGSEError(f"{path}: not every face is a quadrilateral")
    return arr[:, 1:]


def _cell_centres(mesh_dir: Path, owner: np.ndarray) -> np.ndarray:
    """``(n_cells, 3)`` centres of the hexahedra: the mean of their six face centres, m."""
    points = _parse_values(_strip_header((mesh_dir / "points").read_text()), None, 3)
    faces = _read_faces(mesh_dir / "faces")
    neighbour = _read_label_list(mesh_dir / "neighbour")
    fc = points[faces].mean(axis=1)
    n_cells = int(owner.max()) + 1
    acc = np.zeros((n_cells, 3))
    cnt = np.zeros(n_cells)
    np.add.at(acc, owner, fc[: owner.size])
    np.add.at(cnt, owner, 1.0)
    np.add.at(acc, neighbour, fc[: neighbour.size])
    np.add.at(cnt, neighbour, 1.0)
    return acc / cnt[:, None]


def _read_boundary(path: Path) -> dict[str, tuple[int, int]]:
    """``{patch: (startFace, nFaces)}`` of a ``polyMesh/boundary`` file."""
    body = _strip_header(path.read_text())
    out: dict[str, tuple[int, int]] = {}
    for m in re.finditer(r"(\w+)\s*\{([^}]*)\}", body):
        d = dict(re.findall(r"(\w+)\s+([^;]+);", m.group(2)))
        if "startFace" in d and "nFaces" in d:
            out[m.group(1)] = (int(d["startFace"]), int(d["nFaces"]))
    return out


_SOLVE_RE = re.compile(
    r"Solving for (\w+), Initial residual = ([^,]+), Final residual = ([^,]+), "
    r"No Iterations (\d+)"
)


def _flow_log_facts(log: str) -> dict:
    """Iterations, convergence and the last iteration's initial residuals of a simpleFoam log."""
    times = list(re.finditer(r"^Time = (\S+)\s*$", log, flags=re.M))
    iterations = int(float(times[-1].group(1))) if times else 0
    last = log[times[-1].end() :] if times else ""
    residuals: dict[str, float] = {}
    for m in _SOLVE_RE.finditer(last):
        residuals.setdefault(m.group(1), float(m.group(2)))
    converged = "SIMPLE solution converged" in log
    return {"iterations": iterations, "converged": converged, "residuals": residuals}


def _gas_log_facts(log: str, field: str) -> dict:
    solves = [m for m in _SOLVE_RE.finditer(log) if m.group(1) == field]
    if not solves:
        return {"outer_iterations": 0}
    return {
        "outer_iterations": len(solves),
        "first_initial_residual": float(solves[0].group(2)),
        "last_initial_residual": float(solves[-1].group(2)),
        "last_final_residual": float(solves[-1].group(3)),
    }


def _tail(path: Path, n: int = 25) -> str:
    try:
        lines = path.read_text(errors="replace").rstrip().splitlines()
    except OSError:
        return ""
    return "\n".join(lines[-n:])


def _latest_time(case: Path) -> str:
    times = []
    for p in case.iterdir():
        if p.is_dir():
            try:
                times.append((float(p.name), p.name))
            except ValueError:
                pass
    if not times:
        raise DGSEError(f"{case}: no time directory")
    return max(times)[1]


# --------------------------------------------------------------------------------------
# the engine
# --------------------------------------------------------------------------------------
class OpenFOAMEngine:
    """Spec section 4 solved by OpenFOAM v1912 (see the module docstring).

    Args:
        n_procs: processes for the flow solve (``> 1`` runs ``decomposePar``,
            ``mpirun simpleFoam -parallel`` and ``reconstructPar``); the gas runs
            are serial.  Default 1.
        max_iterations: SIMPLEC iteration cap of ``simpleFoam``.
        keep_dir: ``None``/``False``: run in a temporary directory deleted
            afterwards; ``True``: keep that directory; a path: create the case
            folders under it and keep them.  ``Solution.info["case_dir"]`` names it.
        timeout: wall-clock seconds one :meth:`solve` may take (all utilities).
        allow_unconverged: return (instead of raising :class:`ConvergenceError`)
            when the flow misses the residual target within ``max_iterations``.
        gas_correctors: outer (deferred-correction) iterations of each gas solve are
            ``gas_correctors + 1``.
        physics: model parameters (default :data:`DEFAULT_PHYSICS`).
    """

    name = ENGINE_NAME

    @classmethod
    def unavailable(cls) -> str | None:
        """None where the OpenFOAM executables are found, else why not and how to fix it."""
        return None if find_openfoam() is not None else unavailable_reason()

    def __init__(
        self,
        n_procs: int = 1,
        max_iterations: int = 3000,
        keep_dir: str | os.PathLike | bool | None = None,
        timeout: float | None = 3600.0,
        allow_unconverged: bool = False,
        gas_correctors: int = 100,
        physics: Physics = DEFAULT_PHYSICS,
    ) -> None:
        if int(n_procs) < 1:
            raise InputDataError(f"n_procs must be >= 1, got {n_procs}")
        if int(max_iterations) < 1:
            raise InputDataError(f"max_iterations must be >= 1, got {max_iterations}")
        self.n_procs = int(n_procs)
        self.max_iterations = int(max_iterations)
        self.keep_dir = keep_dir
        self.timeout = None if timeout is None else float(timeout)
        self.allow_unconverged = bool(allow_unconverged)
        self.gas_correctors = int(gas_correctors)
        self.physics = physics
        bin_dir = find_openfoam()
        if bin_dir is None:
            raise UnsupportedError(f"engine {ENGINE_NAME!r} is not available: {unavailable_reason()}")
        self.bin_dir = bin_dir
        self._env = openfoam_environment(bin_dir)
        self._deadline: float | None = None
        self._keeping = False

    # -- running utilities ----------------------------------------------------------------
    def _run(
        self, case: Path, utility: str, args: Sequence[str] = (), log_name: str = "", mpi: int = 0
    ) -> float:
        """Run ``utility -case case args`` into ``case/log.<log_name>``; returns seconds."""
        log_path = case / f"log.{log_name or utility}"
        exe = os.path.join(self.bin_dir, utility)
        cmd = [exe, "-case", str(case), *args]
        if mpi > 1:
            mpirun = shutil.which("mpirun", path=self._env["PATH"])
            if mpirun is None:
                raise OpenFOAMError(utility, "n_procs > 1 needs mpirun, which is not on PATH")
            cmd = [mpirun, "--oversubscribe", "-np", str(mpi), *cmd, "-parallel"]
        timeout = None
        if self._deadline is not None:
            timeout = max(1.0, self._deadline - time.monotonic())
        t0 = time.perf_counter()
        with open(log_path, "w") as log:
            try:
                proc = subprocess.run(
                    cmd,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    env=self._env,
                    cwd=case,
                    timeout=timeout,
                    check=False,
                )
            except subprocess.TimeoutExpired:
                raise OpenFOAMTimeoutError(
                    utility,
                    f"stopped after the engine's timeout of {self.timeout:g} s",
                    _tail(log_path),
                    self._log_ref(log_path),
                ) from None
            except OSError as e:
                raise OpenFOAMError(utility, f"could not start {exe} ({e})") from None
        seconds = time.perf_counter() - t0
        text = log_path.read_text(errors="replace")
        if proc.returncode != 0 or "FOAM FATAL" in text:
            raise OpenFOAMError(
                utility, f"exit status {proc.returncode}", _tail(log_path), self._log_ref(log_path)
            )
        return seconds

    def _log_ref(self, log_path: Path) -> str:
        """The log's path when the case is kept (else it is about to be deleted)."""
        return str(log_path) if self._keeping else ""

    # -- the solve ------------------------------------------------------------------------
    def solve(self, layout: Layout, inlet_velocity: float, sources: Sequence[Source]) -> Solution:
        """Flow of ``layout`` at ``inlet_velocity`` m/s and the gas of each source.

        Returns a :class:`Solution` on the layout's ``(H, W)`` grid: wind
        ``(2, H, W)`` m/s, k, epsilon, nut, p ``(H, W)``, one ``(H, W)``
        concentration (ppm) per source, 0 in solid cells.
        """
        sources = list(sources)
        if not (inlet_velocity > 0 and math.isfinite(inlet_velocity)):
            raise InputDataError(f"inlet velocity must be positive, got {inlet_velocity}")
        g = layout.grid
        ventilated = ventilated_cells(layout)
        src_cells = []
        for s in sources:
            i, j = g.cell_of(*s.position)
            x, y = s.position
            if layout.occupancy[i, j]:
                raise InputDataError(f"source at ({x:g}, {y:g}) m lies in a solid cell")
            if not ventilated[i, j]:
                raise InputDataError(
                    f"source at ({x:g}, {y:g}) m lies in a closed region that no inlet reaches: "
                    "its gas has nowhere to go and no steady concentration"
                )
            if not (s.release_rate > 0 and math.isfinite(s.release_rate)):
                raise InputDataError(f"release rate must be positive, got {s.release_rate}")
            src_cells.append((i, j))

        keep = self.keep_dir is not None and self.keep_dir is not False
        parent: Path | None = None
        if keep and not isinstance(self.keep_dir, bool):
            parent = Path(self.keep_dir)  # type: ignore[arg-type]
            parent.mkdir(parents=True, exist_ok=True)
        safe = re.sub(r"[^A-Za-z0-9_.-]", "_", layout.name) or "layout"
        root = Path(tempfile.mkdtemp(prefix=f"dgse-openfoam-{safe}-", dir=parent))
        self._deadline = None if self.timeout is None else time.monotonic() + self.timeout
        self._keeping = keep
        t_start = time.perf_counter()
        try:
            sol = self._solve_in(root / "case", layout, float(inlet_velocity), sources, src_cells)
        except ConvergenceError as e:
            if keep:
                e.info["case_dir"] = str(root / "case")
            raise
        finally:
            self._deadline = None
            if not keep:
                shutil.rmtree(root, ignore_errors=True)
        secs = sol.info["seconds"]
        secs["total"] = time.perf_counter() - t_start
        gas = [float(s) for s in secs.get("gas", [])]
        # the facts every engine reports under the same keys (what case files record)
        sol.info["flow_iterations"] = sol.info["iterations"]["flow"]
        sol.info["flow_converged"] = sol.info["converged"]
        sol.info["wall_clock_s"] = {
            "mesh": secs.get("mesh"),
            "flow": secs.get("flow"),
            "gas": sum(gas),
            "gas_per_source": sum(gas) / max(len(gas), 1),
            "layout_total": secs["total"],
        }
        if keep:
            sol.info["case_dir"] = str(root / "case")
        return sol

    def _patches(self, layout: Layout) -> tuple[list[_Patch], list[_Patch]]:
        g = layout.grid
        inlets = [_Patch(f"inlet{n}", o, *o.cells(g)) for n, o in enumerate(layout.inlets)]
        outlets = [_Patch(f"outlet{n}", o, *o.cells(g)) for n, o in enumerate(layout.outlets)]
        seen: dict[tuple[str, int, int], str] = {}
        for p in inlets + outlets:
            for r, c in zip(p.rows.tolist(), p.cols.tolist(), strict=True):
                key = (p.opening.side, r, c)
                if key in seen:
                    raise InputDataError(
                        f"openings {seen[key]} and {p.name} overlap at cell ({r}, {c}) on the "
                        f"{p.opening.side} side"
                    )
                seen[key] = p.name
        return inlets, outlets

    def _solve_in(
        self, case: Path, layout: Layout, v_in: float, sources: list[Source], src_cells: list[tuple[int, int]]
    ) -> Solution:
        phys = self.physics
        g = layout.grid
        H, W = g.shape
        res = g.resolution
        depth = phys.slab_depth
        inlets, outlets = self._patches(layout)
        # the cells no inlet's air reaches (a closed room) are at rest and gas-free: left out
        # of the mesh as solid cells are, they leave no singular pressure or gas equation
        free = ventilated_cells(layout)
        free_labels = np.flatnonzero(free.ravel())  # blockMesh numbers cells x fastest
        n_cells = int(free_labels.size)
        seconds: dict = {}

        # ---- mesh ------------------------------------------------------------------------
        case.mkdir(parents=True)
        _write(case, "system/controlDict", "dictionary", _control_dict(self.max_iterations))
        _write(case, "system/fvSchemes", "dictionary", _fv_schemes([]))
        _write(case, "system/fvSolution", "dictionary", _fv_solution())
        _write(case, "system/blockMeshDict", "dictionary", _block_mesh_dict(layout, depth))
        _write(
            case,
            "system/topoSetDict.patches",
            "dictionary",
            _topo_set_patches(layout, inlets + outlets, depth),
        )
        _write(case, "system/createPatchDict", "dictionary", _create_patch_dict(inlets + outlets))
        _write(case, "system/topoSetDict.fluid", "dictionary", _topo_set_fluid(free_labels))
        t_mesh = self._run(case, "blockMesh")
        t_mesh += self._run(case, "topoSet", ["-dict", "system/topoSetDict.patches"], "topoSet.patches")
        t_mesh += self._run(case, "createPatch", ["-overwrite"])
        if n_cells < free.size:
            t_mesh += self._run(case, "topoSet", ["-dict", "system/topoSetDict.fluid"], "topoSet.fluid")
            t_mesh += self._run(case, "subsetMesh", ["fluid", "-patch", "walls", "-overwrite"])
        seconds["mesh"] = t_mesh

        mesh_dir = case / "constant" / "polyMesh"
        boundary = _read_boundary(mesh_dir / "boundary")
        for p in inlets + outlets:
            if boundary.get(p.name, (0, 0))[1] == 0:
                raise OpenFOAMError(
                    "createPatch",
                    f"patch {p.name} ({p.opening.describe()}) got no boundary face",
                    _tail(case / "log.createPatch"),
                )
        owner = _read_label_list(mesh_dir / "owner")
        n_mesh_cells = int(owner.max()) + 1 if owner.size else 0
        if n_mesh_cells != n_cells:
            raise OpenFOAMError(
                "subsetMesh",
                f"mesh has {n_mesh_cells} cells, expected {n_cells} free cells",
                _tail(case / "log.subsetMesh"),
            )
        centres = _cell_centres(mesh_dir, owner)
        cols = np.floor(centres[:, 0] / res).astype(np.int64)
        rows = np.floor(centres[:, 1] / res).astype(np.int64)
        if (
            rows.min() < 0
            or cols.min() < 0
            or rows.max() >= H
            or cols.max() >= W
            or not np.array_equal(np.sort(rows * W + cols), free_labels)
        ):
            raise OpenFOAMError(
                "subsetMesh",
                "the cells of the mesh are not the free cells of the layout",
                _tail(case / "log.subsetMesh"),
            )

        # ---- flow ------------------------------------------------------------------------
        states = []
        for p in inlets:
            k_in, eps_in = phys.inlet_turbulence(v_in, p.opening.width_m)
            nx, ny = INWARD_NORMAL[p.opening.side]
            states.append(_InletState((nx * v_in, ny * v_in, 0.0), k_in, eps_in))
        for name, (cls, body) in _flow_fields(inlets, outlets, states, phys).items():
            _write(case, f"0/{name}", cls, body)
        _write(case, "constant/transportProperties", "dictionary", _transport_properties(phys))
        _write(case, "constant/turbulenceProperties", "dictionary", _turbulence_properties(phys))
        if self.n_procs > 1:
            _write(case, "system/decomposeParDict", "dictionary", _decompose_par_dict(self.n_procs, W >= H))
            t_flow = self._run(case, "decomposePar", ["-force"])
            t_flow += self._run(case, "simpleFoam", [], mpi=self.n_procs)
            t_flow += self._run(case, "reconstructPar", ["-latestTime"])
            flow_log = (case / "log.simpleFoam").read_text(errors="replace")
        else:
            t_flow = self._run(case, "simpleFoam")
            flow_log = (case / "log.simpleFoam").read_text(errors="replace")
        seconds["flow"] = t_flow
        facts = _flow_log_facts(flow_log)
        tname = _latest_time(case)
        tdir = case / tname
        flow_info = {
            "engine": ENGINE_NAME,
            "iterations": facts["iterations"],
            "converged": facts["converged"],
            "max_iterations": self.max_iterations,
            "residual_target": RESIDUAL_TARGET,
            "residuals": facts["residuals"],
            "seconds": {"mesh": seconds["mesh"], "flow": seconds["flow"]},
        }
        if not facts["converged"] and not self.allow_unconverged:
            worst = max(facts["residuals"].items(), key=lambda kv: kv[1], default=("?", math.nan))
            raise ConvergenceError(
                f"OpenFOAM simpleFoam did not reach residuals {RESIDUAL_TARGET:g} within "
                f"{self.max_iterations} SIMPLEC iterations for layout {layout.name!r} "
                f"(worst: {worst[0]} {worst[1]:.3g}); raise max_iterations or pass "
                "allow_unconverged=True",
                flow_info,
            )

        U = _read_internal(tdir / "U", n_cells, 3)
        wind = np.zeros((2, H, W))
        wind[0, rows, cols] = U[:, 0]
        wind[1, rows, cols] = U[:, 1]

        def to_grid(name: str) -> np.ndarray:
            out = np.zeros((H, W))
            out[rows, cols] = _read_internal(tdir / name, n_cells)
            return out

        flow = FlowField(
            wind=wind,
            k=to_grid("k"),
            epsilon=to_grid("epsilon"),
            nut=to_grid("nut"),
            pressure=to_grid("p"),
            info=flow_info,
        )

        # boundary data for the mass balance
        def faces(p: _Patch) -> tuple[np.ndarray, np.ndarray]:
            start, n = boundary[p.name]
            return owner[start : start + n], _read_patch_value(tdir / "phi", p.name, n)

        out_faces = [faces(p) for p in outlets]
        in_faces = [faces(p) for p in inlets]
        nut_in = [_read_patch_value(tdir / "nut", p.name, boundary[p.name][1]) for p in inlets]
        face_area = res * depth

        # ---- gas, one postProcess run per source --------------------------------------------
        cell_volume = res * res * depth
        concentrations: list[np.ndarray] = []
        ratios: list[float] = []
        gas_info: list[dict] = []
        gas_seconds: list[float] = []
        for n, (src, (i, j)) in enumerate(zip(sources, src_cells, strict=True)):
            field = f"gas{n}"
            point = ((j + 0.5) * res, (i + 0.5) * res, 0.5 * depth)
            rate = src.release_rate / cell_volume  # g/(m^3 s)
            (tdir / field).write_text(_foam_file("volScalarField", field, _gas_field(inlets, outlets), tname))
            _write(case, "system/fvSchemes", "dictionary", _fv_schemes([field]))
            _write(
                case,
                "system/controlDict",
                "dictionary",
                _control_dict(
                    self.max_iterations, _gas_functions(field, point, rate, phys, self.gas_correctors)
                ),
            )
            t_gas = self._run(case, "simpleFoam", ["-postProcess", "-latestTime"], f"gas{n}")
            gas_seconds.append(t_gas)
            gas_log = (case / f"log.gas{n}").read_text(errors="replace")
            c = _read_internal(tdir / field, n_cells)
            if not np.isfinite(c).all():
                raise OpenFOAMError(
                    "simpleFoam -postProcess",
                    f"gas field {field} is not finite",
                    _tail(case / f"log.gas{n}"),
                    self._log_ref(case / f"log.gas{n}"),
                )
            out_flux = sum(float(np.sum(phi * c[cells])) for cells, phi in out_faces)
            d_in = [phys.D_m + nut / phys.Sc_t for nut in nut_in]
            inlet_loss = sum(
                float(np.sum(d * c[cells] / (0.5 * res) * face_area))
                for (cells, _), d in zip(in_faces, d_in, strict=True)
            )
            ratio = out_flux / src.release_rate
            ratios.append(ratio)
            conc = np.zeros((H, W))
            conc[rows, cols] = c * phys.ppm_per_gm3
            gas_facts = _gas_log_facts(gas_log, field)
            gas_info.append(
                {
                    **gas_facts,
                    "converged": gas_facts.get("last_initial_residual", 1.0) <= GAS_RESIDUAL_OK,
                    "outlet_flux_gps": out_flux,
                    "outlet_flux_ratio": ratio,
                    "inlet_diffusive_loss_ratio": inlet_loss / src.release_rate,
                    "total_out_ratio": (out_flux + inlet_loss) / src.release_rate,
                    "min_raw_ppm": float(conc[rows, cols].min()) if n_cells else 0.0,
                    "source_cell": (i, j),
                    "source_gm3s": rate,
                    "seconds": t_gas,
                }
            )
            concentrations.append(np.clip(conc, 0.0, None))
        seconds["gas"] = gas_seconds

        volume_flux = {
            "inlet": float(sum(np.sum(phi) for _, phi in in_faces)),
            "outlet": float(sum(np.sum(phi) for _, phi in out_faces)),
        }
        info = {
            "engine": ENGINE_NAME,
            "solver": f"openfoam-{_FOAM_VERSION_BANNER} simpleFoam kEpsilon + scalarTransport",
            "flow": flow_info,
            "gas": gas_info,
            "iterations": {
                "flow": facts["iterations"],
                "gas": [gi.get("outer_iterations", 0) for gi in gas_info],
            },
            "converged": facts["converged"],
            "gas_converged": all(gi["converged"] for gi in gas_info),
            "residuals": {
                "flow": facts["residuals"],
                "gas": [gi.get("last_initial_residual") for gi in gas_info],
            },
            "volume_flux_m3s": volume_flux,
            "n_procs": self.n_procs,
            "seconds": seconds,
        }
        return check_mass_balance(
            Solution(
                flow=flow, sources=sources, concentrations=concentrations, outlet_flux_ratio=ratios, info=info
            )
        )
