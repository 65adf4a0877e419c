"""SITL instance numbers shared by the processes of one machine (ft_sitl.mavlink.instances):
a SITL on fixed numbers (``ft-sitl sitl --instance``, the tests' servers) holds them, a
trial over MAVLink takes the next free one, and a second holder is refused by name."""

import subprocess
import sys
import time

import pytest

from ft_sitl.mavlink.instances import InstanceBusy, InstanceLock, instances_held

FIRST = 960  # (numbers no test server or trial uses)


@pytest.mark.e2e  # (InstanceLock tries each number's ports: a bind)
def test_a_trial_skips_held_numbers_and_a_second_holder_is_refused_by_name():
    with instances_held(FIRST, 2) as held:
        assert held == [FIRST, FIRST + 1]
        with InstanceLock(base=FIRST, slots=3) as i:
            assert i == FIRST + 2  # the trial's pick: past the held ones
        with pytest.raises(InstanceBusy, match=f"SITL instance {FIRST + 1} \\(ports "
                                               f"{14540 + FIRST + 1}, "):
            with instances_held(FIRST + 1, 1, wait_s=0.2):
                pass
        with pytest.raises(RuntimeError, match=f"no free SITL instance in {FIRST}"):
            with InstanceLock(base=FIRST, slots=2):
                pass
    with instances_held(FIRST, 2):  # let go: free again
        pass


@pytest.mark.e2e
def test_another_process_holding_the_number_is_waited_for_then_released():
    hold = subprocess.Popen([sys.executable, "-c", (
        "import sys, time\n"
        "from ft_sitl.mavlink.instances import instances_held\n"
        f"with instances_held({FIRST}):\n"
        "    print('held', flush=True)\n"
        "    time.sleep(1.5)\n")], stdout=subprocess.PIPE, text=True)
    try:
        assert hold.stdout.readline().strip() == "held"
        with pytest.raises(InstanceBusy):
            with instances_held(FIRST, wait_s=0.1):
                pass
        t0 = time.monotonic()
        with instances_held(FIRST, wait_s=30.0):  # the other process exits: ours
            assert time.monotonic() - t0 > 0.5
    finally:
        hold.kill()
        hold.wait()


def test_sitl_on_a_number_another_process_holds_is_a_one_line_error(capsys):
    from ft_sitl.cli import main

    with instances_held(FIRST):
        assert main(["sitl", "--instance", str(FIRST), "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"ft-sitl: error: --instance: SITL instance {FIRST} (ports "
                          f"{14540 + FIRST}, {14580 + FIRST}, {18570 + FIRST}) is in use by "
                          "another ft-sitl process") and err.count("\n") == 1, err


def test_a_bad_option_is_named_before_a_held_number(capsys):
    """Every option is checked before the instance numbers are taken: a bad one is the
    error even while another SITL holds the number (the user fixes the option first)."""
    from ft_sitl.cli import main

    with instances_held(FIRST):
        for option, value, named in (("--home", "nan,8.5,488", "--home: home latitude"),
                                     ("--platform", "no-such-platform", "no-such-platform")):
            assert main(["sitl", "--instance", str(FIRST), option, value]) == 2
            err = capsys.readouterr().err
            assert err.startswith("ft-sitl: error: ") and named in err \
                and "in use" not in err and err.count("\n") == 1, err
