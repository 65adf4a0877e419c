"""The package's layering (docs/architecture.md): imports point down only.

physics <- autopilot <- sim <- mavlink / bridge / missions / cli, with scenarios (geometry)
beside autopilot, navigation and the bus above them, the wire client above those, the
transport room (a trial flown over MAVLink, the simulator's side of the bus) and the
Gymnasium environments (gym) above the missions. Checked
statically on every import statement of the package (in functions too) and dynamically
by importing the lower layers in a fresh interpreter.
"""

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "ft_sitl"
#: modules directly under ft_sitl/ that every layer may use
BASE = {"ft_sitl", "frames", "numeric_env", "jit_cache", "config", "schema", "rotations",
        "provenance", "mover_kinds", "markdown", "__version__", "G"}
#: what each part of the package may import besides BASE and itself
ALLOWED = {
    "physics": set(),
    "autopilot": {"physics"},
    "scenarios": {"physics"},
    "sim": {"physics", "autopilot", "scenarios"},
    "navigation": {"physics", "autopilot", "scenarios"},
    "bus": {"physics", "scenarios"},
    "mavlink": {"physics", "autopilot", "scenarios", "sim"},
    "bridge": {"physics", "autopilot", "scenarios", "sim"},
    "wire": {"physics", "autopilot", "scenarios", "sim", "navigation", "bus"},
    # the missions fly no transport: the MAVLink trial is the transport room's, above
    "missions": {"physics", "autopilot", "scenarios", "sim", "navigation"},
    "transport": {"physics", "autopilot", "scenarios", "sim", "navigation", "bus", "mavlink",
                  "wire", "missions"},
    "gym": {"physics", "autopilot", "scenarios", "sim", "navigation", "bus", "mavlink",
            "wire", "missions"},
    "demo": {"physics", "autopilot", "sim"},
    "cli": {"physics", "autopilot", "scenarios", "sim", "navigation", "bus", "mavlink",
            "bridge", "wire", "missions", "transport", "gym", "demo"},
    "__main__": {"cli"},
}


def part_of(module: str) -> str:
    """The layer a dotted ft_sitl module name belongs to."""
    parts = module.split(".")
    if len(parts) == 1:
        return "ft_sitl"
    return parts[1]


def modules():
    for path in sorted(PKG.rglob("*.py")):
        rel = path.relative_to(PKG.parent).with_suffix("")
        name = ".".join(rel.parts)
        if name.endswith(".__init__"):
            name = name[: -len(".__init__")]
        yield name, path


def own_imports(path: Path):
    """(line, imported ft_sitl module, imported names) of every import in the file."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0 \
                and node.module.split(".")[0] == "ft_sitl":
            yield node.lineno, node.module, [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "ft_sitl":
                    yield node.lineno, a.name, []


def test_every_part_has_a_layer():
    parts = {part_of(name) for name, _ in modules()} - {"ft_sitl"}
    assert parts - BASE <= set(ALLOWED), parts - BASE - set(ALLOWED)


def test_imports_point_down_only():
    bad = []
    for name, path in modules():
        me = part_of(name)
        if me in BASE:
            allowed = BASE
        else:
            allowed = BASE | ALLOWED[me] | {me}
        for line, mod, names in own_imports(path):
            targets = [mod] if mod != "ft_sitl" else [f"ft_sitl.{n}" for n in names]
            for t in targets:
                if part_of(t) not in allowed:
                    bad.append(f"{path.relative_to(PKG.parent)}:{line} imports {t}")
    assert not bad, "\n".join(bad)


def test_no_private_name_is_imported_from_another_module():
    bad = []
    for _, path in modules():
        for line, mod, names in own_imports(path):
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            private += [p for p in mod.split(".") if p.startswith("_") and p != "__init__"]
            if private:
                bad.append(f"{path.relative_to(PKG.parent)}:{line}: {', '.join(private)} "
                           f"from {mod}")
    assert not bad, "\n".join(bad)


@pytest.mark.e2e
@pytest.mark.parametrize("layer,forbidden", [
    ("physics", ("sim", "autopilot", "missions", "navigation", "mavlink", "wire", "cli")),
    ("autopilot", ("sim", "missions", "navigation", "mavlink", "wire", "cli")),
    ("scenarios", ("sim", "autopilot", "missions", "navigation", "mavlink", "wire", "cli")),
])
def test_lower_layers_import_alone(layer, forbidden):
    """Every module of a lower layer imported in a fresh interpreter pulls in no module
    of the layers above it."""
    names = [n for n, _ in modules() if part_of(n) == layer]
    loaded = [m for m in modules_loaded_by(*names) if m.startswith("ft_sitl.")]
    above = [m for m in loaded if part_of(m) in forbidden]
    assert len(names) > 2 and not above, above


def modules_loaded_by(*names: str) -> list[str]:
    """Every module (ft_sitl's and third-party) in sys.modules after importing ``names``
    alone in a fresh interpreter."""
    code = ("import importlib, json, sys\n"
            f"for n in {list(names)!r}: importlib.import_module(n)\n"
            "print(json.dumps(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, cwd=PKG.parent)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.e2e
def test_navigator_protocol_loads_no_map():
    """The Navigator protocol (navigation.base), which every transport imports, loads
    no module of the maps room (navigation.maps: the local map's numba kernels, the ESDF)
    nor anything importing one: a task's map lives with the map."""
    loaded = modules_loaded_by("ft_sitl.navigation.base")
    assert "ft_sitl.navigation.base" in loaded
    maps = [m for m in loaded if m.startswith("ft_sitl.navigation.maps")]
    assert not maps, sorted(m for m in loaded if m.startswith("ft_sitl."))


NAVIGATION = PKG / "navigation"


def _plant_layout_lines(path: Path) -> list[int]:
    """Lines of a module that name the plant's state or status indices (``X_*``, ``S_*`` of
    physics.dynamics), imported by name or read through the module (``d.X_POS``)."""
    tree = ast.parse(path.read_text())
    dyn = "ft_sitl.physics.dynamics"
    names, aliases, lines = set(), {dyn}, []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module == dyn:
            names |= {a.asname or a.name for a in node.names if a.name[:2] in ("X_", "S_")}
        elif isinstance(node, ast.ImportFrom) and f"{node.module}.dynamics" == dyn:
            aliases |= {a.asname or a.name for a in node.names if a.name == "dynamics"}
        elif isinstance(node, ast.Import):
            aliases |= {a.asname for a in node.names if a.name == dyn and a.asname}
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and node.id in names:
            lines.append(node.lineno)
        elif isinstance(node, ast.Attribute) and node.attr[:2] in ("X_", "S_") \
                and ast.unparse(node.value) in aliases:
            lines.append(node.lineno)
    return sorted(set(lines))


def test_navigators_read_no_plant_arrays_but_in_compiled_kernels():
    """A navigator reads the vehicle from its Observation, not from the plant's state
    arrays (``X_*``/``S_*`` of physics.dynamics), except in a compiled numba kernel shared
    with the batched simulator (policy_io.observe_state) and where the kernel's input is
    filled; each such place says why in a comment on the kernel (its decorator or the
    lines above) or on the statement (that line or the two above a run of them)."""
    bad = []
    for path in sorted(NAVIGATION.rglob("*.py")):
        text = path.read_text().splitlines()
        tree = ast.parse("\n".join(text))
        kernels = [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)
                   and any("njit" in ast.unparse(d) for d in n.decorator_list)]

        def said(first: int, last: int, text=text) -> bool:  # a comment on lines first..last
            return any(ln.strip().startswith("#") or " # " in ln
                       for ln in text[max(first - 1, 0):last])

        uses = _plant_layout_lines(path)
        for line in uses:
            if text[line - 1].lstrip().startswith(("from ", "import ")):
                continue  # the import: judged by its uses
            k = next((n for n in kernels if n.lineno <= line <= n.end_lineno), None)
            top = k.decorator_list[0].lineno if k else line
            while not k and top - 1 in uses:  # a run of such statements shares its comment
                top -= 1
            if not said(top - 3, top - 1 if k else line):
                bad.append(f"{path.relative_to(PKG.parent)}:{line}: {text[line - 1].strip()}")
    assert not bad, "plant arrays indexed outside a commented kernel:\n" + "\n".join(bad)


@pytest.mark.e2e
def test_bus_codec_loads_no_scenario_code():
    """The bus's payloads (bus.codec), which every subscriber imports, load no scenarios
    module and not trimesh: the movers' shapes and count limit come from ft_sitl.mover_kinds,
    the camera's DepthFrame only when a frame is rebuilt (to_depth_frame)."""
    loaded = modules_loaded_by("ft_sitl.bus.codec")
    assert "ft_sitl.bus.codec" in loaded
    heavy = [m for m in loaded if m == "ft_sitl.scenarios" or m.startswith("ft_sitl.scenarios.")
             or m == "trimesh" or m.startswith("trimesh.")]
    assert not heavy, heavy


def test_in_function_imports_say_why():
    """An import inside a function only where it breaks a real cost (a heavy or optional
    dependency, the command line's start-up time), with its reason in a comment on its
    line or the line above; everything else is imported at the top of the module."""
    bad = []
    for _, path in modules():
        lines = path.read_text().splitlines()
        for node in ast.walk(ast.parse("\n".join(lines))):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for sub in ast.walk(node):
                if isinstance(sub, (ast.Import, ast.ImportFrom)):
                    here = lines[sub.lineno - 1]
                    # the reason stands on the line, or above it (and above the imports
                    # of its group)
                    k = sub.lineno - 2
                    while k >= 0 and lines[k].strip().startswith(("from ", "import ")):
                        k -= 1
                    above = lines[k].strip() if k >= 0 else ""
                    if "#" not in here and not above.startswith("#"):
                        bad.append(f"{path.relative_to(PKG.parent)}:{sub.lineno}: "
                                   f"{here.strip()}")
    assert not bad, f"{len(bad)} in-function imports without a reason:\n" + "\n".join(
        sorted(set(bad)))


#: the parts that reach a vehicle's state only through the fleet's (or the simulation's)
#: named read-outs, never through the plant's array layout (docs/architecture.md, mavlink/);
#: transport/ holds the simulator's side of the bus that wire/ had
NAMED_STATE_ONLY = ("mavlink", "wire", "bridge", "transport")
def test_wire_layers_read_state_through_named_accessors():
    """mavlink/, wire/, bridge/ and transport/ never index the plant's state arrays: they
    ask the fleet (attitude(i), body_rates(i), rotor_speeds(i), specific_force(i),
    state(i)) or the simulation (position(i), ...), so the array layout is physics' and
    sim's alone."""
    bad = []
    for name, path in modules():
        if part_of(name) not in NAMED_STATE_ONLY:
            continue
        rel = str(path.relative_to(PKG.parent))
        bad += [f"{rel}:{line}" for line in _plant_layout_lines(path)]
    assert not bad, "plant arrays indexed:\n" + "\n".join(bad)
