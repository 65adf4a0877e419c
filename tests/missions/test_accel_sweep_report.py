"""scripts/accel_sweep_report.py on committed results: the protocol-1 and protocol-4 paper
samples (docs/results/paper-sample*, 1,260 real trials each) read as two conditions of the
acceleration-limit sweep."""

import importlib.util
import json
import math
from pathlib import Path

import pandas as pd
import pytest

from ft_sitl.physics.catalog import catalog

ROOT = Path(__file__).resolve().parents[2]
V1, V4 = ROOT / "docs" / "results" / "paper-sample", ROOT / "docs" / "results" / "paper-sample-v4"
_spec = importlib.util.spec_from_file_location("accel_sweep_report",
                                               ROOT / "scripts" / "accel_sweep_report.py")
report = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(report)


@pytest.fixture(scope="module")
def sweep():
    return report.load_sweep([V1, V4])


def test_each_directory_is_one_condition_of_the_classic_families(sweep):
    assert report.conditions_in_order(sweep) == ["own limits, bandwidth", "3 m/s^2, bandwidth"]
    assert set(sweep["family"]) == set(report.CLASSIC)
    # 5 algorithms x 36 platforms x 3 families, one trial each, per condition
    assert sweep.groupby("condition").size().to_dict() == {
        "own limits, bandwidth": 540, "3 m/s^2, bandwidth": 540}
    assert report.algorithms_in_order(sweep) == ["straight", "ego", "fast", "pgo", "navrl"]
    radius = {n: p.collision_radius_m for n, p in catalog().items()}
    assert (sweep["footprint_m"] == sweep["platform"].map(radius)).all()


def test_per_platform_success_is_the_share_of_its_trials(sweep):
    pp = report.per_platform(sweep)
    assert len(pp) == 2 * 5 * 36 and (pp["trials"] == 3).all()
    raw = pd.read_parquet(V4 / "trials.parquet")
    raw = raw[raw["family"].isin(report.CLASSIC)]
    for (alg, plat), g in raw.groupby(["algorithm", "platform"], observed=True):
        row = pp[(pp["condition"] == "3 m/s^2, bandwidth") & (pp["algorithm"] == alg)
                 & (pp["platform"] == plat)]
        assert row["success"].item() == pytest.approx(g["success"].mean())
        assert row["twr_max"].item() == g["twr_max"].iloc[0]


def test_correlations_and_regressions_per_condition_and_algorithm(sweep):
    pp = report.per_platform(sweep)
    cor, reg = report.correlations(pp), report.regressions(pp)
    assert len(cor) == len(reg) == 10
    straight = reg[reg["algorithm"] == "straight"]
    assert (straight["note"] == "success is 0.00 on every platform").all()
    assert cor[cor["algorithm"] == "straight"]["rho_twr_max"].isna().all()
    fitted = reg[reg["note"] == ""]
    assert len(fitted) >= 6
    for col in ("beta_twr_max", "beta_alpha_xy_max", "beta_alpha_z_max", "beta_footprint_m",
                "r2"):
        assert fitted[col].notna().all()
    assert ((fitted["r2"] >= 0) & (fitted["r2"] <= 1)).all()
    vif = report.inflation_factors(pp)
    assert set(vif) == {c for c, _, _ in report.INDICATORS}
    assert all(v >= 1.0 for v in vif.values())


def test_a_directory_of_two_conditions_or_one_given_twice_is_refused(tmp_path):
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    both = pd.concat([pd.read_parquet(V1 / "trials.parquet").head(20),
                      pd.read_parquet(V4 / "trials.parquet").head(20)], ignore_index=True)
    both.to_parquet(mixed / "trials.parquet")
    with pytest.raises(report.SweepError, match="holds 2 conditions"):
        report.load_sweep([mixed])
    with pytest.raises(report.SweepError, match="condition '3 m/s\\^2, bandwidth' is also"):
        report.load_sweep([V4, V4])
    with pytest.raises(report.SweepError, match="not a result directory"):
        report.load_sweep([tmp_path / "nothing"])


def test_a_spec_names_its_condition():
    spec = json.loads(pd.read_parquet(V4 / "trials.parquet", columns=["spec"])["spec"].iloc[0])
    assert report.condition_of(spec) == (3.0, "bandwidth")
    assert report.condition_of({**spec, "gains": "px4",
                                "limits": {**spec["limits"], "max_acc_m_s2": 6}}) == (6.0, "px4")
    acc, gains = report.condition_of({k: v for k, v in spec.items() if k != "limits"})
    assert math.isnan(acc) and gains == "bandwidth"


@pytest.mark.slow
def test_the_report_is_written(tmp_path):
    assert report.main([str(V1), str(V4), "--out", str(tmp_path)]) == 0
    text = (tmp_path / "summary.md").read_text()
    assert "| own limits, bandwidth | `" in text and "## OLS of per-platform success" in text
    pngs = sorted(p.name for p in tmp_path.glob("*.png"))
    assert pngs == sorted(["success_vs_indicators.png"] + [
        f"success_vs_indicators_{a}.png" for a in ("straight", "ego", "fast", "pgo", "navrl")])
    assert len(pd.read_csv(tmp_path / "per_platform.csv")) == 360
