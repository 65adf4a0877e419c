"""``campaign run --reuse DIR``: the rows another result directory holds of this campaign's
trials are taken, not flown again (the envelope's thrust-floor re-flight keeps every trial
the floor leaves alone); a row whose spec no longer hashes to its id is flown again, and a
bad directory is a one-line error before anything is written."""

import json

from ft_sitl.cli import main
from tests.missions.conftest import campaign_file, read_jsonl

TWO = """\
name = "floor"
algorithms = ["straight"]
platforms = ["series-0.55kg-UAV1-twr2.0", "series-0.55kg-UAV1-twr6.0"]
scenarios = [{file = "yard.yaml"}]
trials = 1
[limits]
timeout_s = 2.0
"""
#: the same campaign with the floor per platform: the TWR-2 trial keeps its spec and id
WEIGHT = TWO.replace("trials = 1\n", 'trials = 1\nthrust_floor = "weight"\n')


def _run(campaign, out, *extra):
    return main(["campaign", "run", str(campaign), "--out", str(out), "--no-report",
                 "--quiet", *map(str, extra)])


def _by_platform(directory):
    return {r["platform"]: r for r in read_jsonl(directory / "trials.jsonl")}


def test_only_the_trials_that_differ_are_flown_and_the_others_are_taken_as_they_were(
        yard, capsys, tmp_path):
    root = yard.parent  # (the campaign files beside the yard: its path is relative)
    px4, weight = tmp_path / "px4", tmp_path / "weight"
    assert _run(campaign_file(root, "reuse-px4.toml", TWO), px4) == 0
    capsys.readouterr()
    assert _run(campaign_file(root, "reuse-weight.toml", WEIGHT), weight, "--reuse", px4) == 0
    out, err = capsys.readouterr()
    assert out.startswith("1 trials run, 1 already done, 2 in the campaign;"), out
    assert f"note: 1 trial taken from {px4} (--reuse)" in err
    old, new = _by_platform(px4), _by_platform(weight)
    assert new["series-0.55kg-UAV1-twr2.0"] == old["series-0.55kg-UAV1-twr2.0"]
    flown = new["series-0.55kg-UAV1-twr6.0"]
    assert flown["trial_id"] != old["series-0.55kg-UAV1-twr6.0"]["trial_id"]
    assert json.loads(flown["params"]) == {"MPC_THR_MIN": 0.06}
    run = json.loads((weight / "runs.json").read_text())[-1]
    assert (run["trials_run"], run["trials_skipped"], run["trials_reused"]) == (
        1, 1, {str(px4): 1})
    # taken rows are the directory's own now: a resume flies nothing
    assert _run(root / "reuse-weight.toml", weight, "--reuse", px4) == 0
    assert capsys.readouterr().out.startswith("0 trials run, 2 already done, 2 in the "
                                              "campaign;")


def test_a_row_whose_spec_does_not_hash_to_its_id_is_flown_again(yard, capsys, tmp_path):
    root = yard.parent
    src, out = tmp_path / "src", tmp_path / "out"
    assert _run(campaign_file(root, "reuse-a.toml", TWO), src) == 0
    lines = (src / "trials.jsonl").read_text().splitlines()
    rows = [json.loads(ln) for ln in lines]
    for r in rows:  # written under another canonical form: the spec says another seed
        spec = json.loads(r["spec"])
        spec["seed"] += 1
        r["spec"] = json.dumps(spec)
    (src / "trials.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    capsys.readouterr()
    assert _run(root / "reuse-a.toml", out, "--reuse", src) == 0
    out_text, err = capsys.readouterr()
    assert out_text.startswith("2 trials run, 0 already done"), out_text
    assert f"note: 0 trials taken from {src} (--reuse)" in err


def test_bad_reuse_directories_are_named_before_anything_is_written(yard, capsys, tmp_path):
    campaign = campaign_file(yard.parent, "reuse-c.toml", TWO)
    out = tmp_path / "out"
    plain = tmp_path / "plain"
    plain.mkdir()
    for src, message in ((tmp_path / "nowhere", "not a campaign result directory (no "
                                                 "campaign.json)"),
                         (plain, "not a campaign result directory"),
                         (out, "is the campaign's own --out directory")):
        assert _run(campaign, out, "--reuse", src) == 2
        err = capsys.readouterr().err
        assert f"--reuse {src}: {message}" in err, err
        assert len(err.strip().splitlines()) == 1, err
        assert not out.exists()
