"""What ground stations ask PX4 SITL for besides flying: the MAVLink shell (MAVSDK's Shell
plugin: `ver all`, `param show`/`set`, `commander`, a clear refusal for the rest) and
sensor calibration (MAVSDK's Calibration plugin completes at once, as against PX4 SITL;
refused when armed)."""

import asyncio

import pytest
from mavsdk.asyncio.plugins.calibration import CalibrationAsync
from mavsdk.asyncio.plugins.shell import ShellAsync
from mavsdk.plugins.calibration import CalibrationError, CalibrationResult
from mavsdk.plugins.shell import Device

from .mavsdk_util import connect
from .sitl_harness import running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

INSTANCE = 60  # (ports of its own: other sessions use the default ones)


def test_shell_and_calibration_with_mavsdk():
    async def run(server):
        m, drone = await connect(14540 + INSTANCE)
        shell, cal = ShellAsync(drone), CalibrationAsync(drone)
        out = []

        async def listen():
            async for r in shell.subscribe_receive():
                out.append(r.data)

        task = asyncio.create_task(listen())
        await asyncio.sleep(0.5)

        async def ask(line, expect):
            n = len(out)
            await shell.send(line + "\n", Device.SHELL)
            for _ in range(100):
                if expect in "".join(out[n:]):
                    return "".join(out[n:])
                await asyncio.sleep(0.05)
            raise AssertionError(f"{line!r}: no {expect!r} in {''.join(out[n:])!r}")

        assert "FW version: 1.15.0" in await ask("ver all", "nsh> ")
        assert "MPC_XY_VEL_MAX [0]: 4.0" in await ask("param show MPC_XY_VEL_MAX", "nsh> ")
        await ask("param set MPC_XY_CRUISE 4.5", "nsh> ")
        assert server.fleet.params[0]["MPC_XY_CRUISE"] == 4.5
        assert "outside" in await ask("param set MPC_XY_CRUISE 99", "nsh> ")
        assert "armed: False" in await ask("commander status", "nsh> ")
        assert "nsh: rm: command not found" in await ask("rm -rf /", "nsh> ")
        steps = [(r, d) async for r, d in cal.calibrate_gyro()]
        assert steps[-1][0] == CalibrationResult.SUCCESS
        # ("[cal] progress <50>" reaches MAVSDK's callers as the fraction 0.5)
        assert any(d.has_progress and d.progress == pytest.approx(0.5) for _, d in steps)
        steps = [(r, d) async for r, d in cal.calibrate_magnetometer()]
        assert steps[-1][0] == CalibrationResult.SUCCESS
        assert "ACCEPTED" in await ask("commander arm", "nsh> ")
        with pytest.raises(CalibrationError, match="FAILED_ARMED|DENIED|BUSY"):
            async for _ in cal.calibrate_gyro():
                pass
        task.cancel()
        m.destroy()

    with running_sitl(base_instance=INSTANCE) as server:
        asyncio.run(run(server))
