"""The scenario families' declared parameters: pinned geometry, provenance from the
declaration, validation of overrides, display."""

from __future__ import annotations

from pathlib import Path

import pytest

from ft_sitl.scenarios.families import (
    CATEGORY,
    FAMILIES,
    PAPER_NAMES,
    REGISTRY,
    build_scenario,
    describe_family,
)
from ft_sitl.scenarios.scenario import ScenarioError

# mesh digest, start and goal captured at 5da4228, before the parameters were declared: an
# edit of a generator must not change the geometry of the paper's configurations (version
# 1's; a generator that builds other meshes is a new version). (With
# OpenBLAS's own kernel choice -- numpy imported before ft_sitl -- Random-Angle Cylinder
# builds other meshes; see ft_sitl.numeric_env.)
PINNED = [
    ("forest", 1, "026cb435637a64e13f6b4d0f2334e2b4e5d7f003345e58dccc2ca55c5ec5b4e8",
     (20.0, 3.0, 1.5), (20.0, 57.0, 1.5)),
    ("forest", 7, "c33f8132a20a1bad43db7e91f5cbc942651739a5ede5df54590cfe6e5b5d722b",
     (20.0, 3.0, 1.5), (20.0, 57.0, 1.5)),
    ("urban", 3, "cab2763159c39c6331d2ddbcfbcad12da50547c06ce592659f28cc636fc3848d",
     (30.0, 3.0, 2.0), (30.0, 57.0, 2.0)),
    ("random_angle_cylinder", 4,
     "9bf74edc1621269eb9c9859efcfa5beff060e52832ef086722ecd749e104dc45",
     (20.0, 3.0, 1.5), (20.0, 57.0, 1.5)),
    ("narrow_gap", 5, "afbab07d56b5345549401a7b22ae8673e596e3cf5512e57c453e61bba1ca32b4",
     (25.0, 3.0, 2.0), (25.0, 47.0, 2.0)),
    ("sudden_drop", 10, "49e473ec4dd7b8733d2e53e769078b3f64ef43eb826e223d652b96c12371b86a",
     (25.0, 3.0, 2.5), (25.0, 47.0, 2.5)),
    ("maze", 2, "517a73019ef92905cb38df23abcc596f1ead248e9abbeae7198fc537fd28ec2c",
     (12.500000000000002, 1.1764705882352942, 1.0),
     (12.500000000000002, 38.82352941176471, 1.0)),
    ("perlin", 6, "9f94e63a7dd44f35606b089f687760cf8c63a48106cd80a391b86c42ad0ac57b",
     (20.0, 3.0, 2.0), (20.0, 47.0, 2.0)),
]

# provenance parameters as the generators typed them before (same capture)
PINNED_PARAMETERS = {
    ("sudden_drop", 3): {
        "size_m": [50.0, 50.0, 14.0], "ceiling_m": 4.0, "volume_height_m": 14.0,
        "lowest_obstacle_m": 1.5, "start_altitude_m": 2.5, "block_count": 3,
        "block_depth_m": [1.5, 3.0], "block_zone_y_m": [8.0, 44.0]},
    ("maze", 1): {
        "size_m": [25.0, 40.0], "ceiling_m": 2.0, "cells": [11, 17],
        "cell_m": [2.272727272727273, 2.3529411764705883],
        "corridor_width_m": 2.0727272727272728, "wall_thickness_m": 0.2, "wall_height_m": 2.5,
        "algorithm": "recursive backtracker", "start_altitude_m": 1.0},
    ("urban", 1): {
        "size_m": [60.0, 60.0], "ceiling_m": 10.0, "block_zone_x_m": [4.0, 56.0],
        "block_zone_y_m": [8.0, 52.0], "park_probability": 0.15, "tall_probability": 0.75,
        "tall_height_m": [12.0, 40.0], "low_height_m": [3.0, 7.0], "alley_m": 1.2,
        "wall_height_m": [2.0, 6.0], "wall_length_m": [3.0, 10.0],
        "boulevard_probability": 0.35, "line_corridor_m": 0.6, "start_altitude_m": 2.0},
}


@pytest.mark.parametrize("family,index,digest,start,goal", PINNED)
def test_the_paper_configurations_are_unchanged(family, index, digest, start, goal):
    sc = build_scenario(family, index, version=1)
    assert sc.mesh_digest() == digest
    assert tuple(sc.start) == start and tuple(sc.goal) == goal


@pytest.mark.parametrize("key", list(PINNED_PARAMETERS))
def test_provenance_parameters_are_unchanged(key):
    params = build_scenario(*key, version=1).provenance["parameters"]
    assert list(params.items()) == list(PINNED_PARAMETERS[key].items())
    assert [type(v) for v in params.values()] == [type(v) for v in
                                                  PINNED_PARAMETERS[key].values()]


@pytest.mark.parametrize("family", [pytest.param(f, marks=pytest.mark.slow) if f == "perlin"
                                    else f for f in REGISTRY])  # (a Perlin world: seconds)
def test_provenance_records_every_declared_parameter_in_order(family):
    fam = REGISTRY[family]
    prov = build_scenario(family, 2).provenance
    assert list(prov["parameters"]) == [p.name for p in fam.schema]
    assert prov["paper_name"] == fam.paper_name
    defaults = fam.schema.defaults()
    for name, value in prov["parameters"].items():
        if name in defaults:
            expected = defaults[name]
            assert value == (list(expected) if isinstance(expected, tuple) else expected)


def test_the_views_follow_the_registry():
    assert list(FAMILIES) == list(REGISTRY) == list(CATEGORY) == list(PAPER_NAMES)
    for name, fam in REGISTRY.items():
        assert FAMILIES[name] is fam.build and CATEGORY[name] == fam.category
        assert PAPER_NAMES[name] == fam.paper_name


def test_an_override_reaches_the_draws_and_the_provenance():
    sc = build_scenario("forest", 1, params={"trunk_radius_m": [0.2, 0.2], "ceiling_m": 4.0})
    radii = {round(t[2], 12) for t in sc.provenance["layout"]["trees_xyrh"]}
    assert radii == {0.2}
    assert sc.provenance["parameters"]["trunk_radius_m"] == [0.2, 0.2]
    assert sc.provenance["parameters"]["start_altitude_m"] == 2.0 and sc.ceiling == 4.0
    assert sc.mesh_digest() != PINNED[0][2]
    same = build_scenario("forest", 1, params={"trunk_radius_m": [0.15, 0.30]})
    assert same.mesh_digest() == PINNED[0][2]


@pytest.mark.parametrize("params,message", [
    ({"trunk_radius": [0.1, 0.2]},
     "scenario family 'forest' has no parameter 'trunk_radius'; did you mean "
     "'trunk_radius_m'? (parameters: size_m, ceiling_m, density_per_m2, trunk_radius_m,"),
    ({"trunk_radius_m": [0.3, 0.1]},
     "scenario family 'forest': trunk_radius_m: must be [lo, hi] with 0.02 <= lo <= hi <= 2 "
     "(m), got [0.3, 0.1]"),
    ({"density_per_m2": 1.0},
     "scenario family 'forest': density_per_m2: must be a number 0.0001..0.2 (1/m^2), "
     "got 1.0"),
    ({"min_trunk_gap_m": "1.5"},
     "scenario family 'forest': min_trunk_gap_m: must be a number 0..20 (m), got '1.5'"),
    ({"tree_count": 10},
     "scenario family 'forest': tree_count is derived from the other parameters"),
])
def test_invalid_overrides_are_refused_by_name(params, message):
    with pytest.raises(ScenarioError) as exc:
        build_scenario("forest", 1, params=params)
    assert str(exc.value).startswith(message)


def test_a_generator_called_directly_checks_its_parameters():
    with pytest.raises(ScenarioError, match="maze': cells: must be 2 numbers, each 2..200"):
        FAMILIES["maze"](1, 0, {"cells": (11.5, 17)})


@pytest.mark.parametrize("family", list(REGISTRY))
def test_describe_lists_every_parameter_with_unit_and_range(family):
    fam = describe_family(fam_name := REGISTRY[family].paper_name)
    assert fam is REGISTRY[family], fam_name
    rows = fam.schema.rows()
    assert [r["name"] for r in rows] == [p.name for p in fam.schema]
    for r in rows:
        assert r["unit"] and r["range"] and r["doc"], r
    assert any(r["range"] == "derived" for r in rows)


def test_describe_refuses_an_unknown_family():
    with pytest.raises(ScenarioError, match="unknown scenario family 'forrest'; did you mean"):
        describe_family("forrest")


def test_the_documented_tables_are_the_declarations():
    text = (Path(__file__).resolve().parents[2] / "docs" / "scenarios.md").read_text()
    for name, fam in REGISTRY.items():
        block = (f"<!-- BEGIN generated: describe_family({name!r}).schema.markdown() -->\n"
                 f"{fam.schema.markdown()}\n<!-- END generated -->")
        assert block in text, f"docs/scenarios.md: regenerate the table of {name!r}"
