"""Fixtures of the bus tests: real brokers and a real depth frame.

``mosquitto``: one mosquitto process for the session on a free localhost port (temporary
config: ``listener <port> 127.0.0.1``, ``allow_anonymous true``; mosquitto 2.x refuses
anonymous clients without it). ``mosquitto_factory``: fresh mosquitto processes for tests
that kill, freeze or restart their broker (each torn down after the test). ``amqtt``: the
package's own ``EmbeddedBroker`` for the session. ``broker`` is parametrised over both.
``depth_sample``: a 160 x 120 frame rendered by the real depth camera in a small scene.

Waits poll a condition against a generous deadline (``DEADLINE_S``); nothing asserts how
long something took.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

from ft_sitl.bus import EmbeddedBroker
from ft_sitl.scenarios.camera import CameraConfig, DepthCamera

from .busutil import DEADLINE_S, free_port


def mosquitto_binary() -> str:
    exe = shutil.which("mosquitto") or shutil.which("mosquitto", path="/usr/sbin:/sbin")
    if exe is None:
        pytest.fail("the mosquitto broker is not installed: run scripts/setup.sh --test "
                    "(apt-get install mosquitto)")
    return exe


class Mosquitto:
    """A mosquitto process on 127.0.0.1:``port`` (optionally a TLS listener)."""

    def __init__(self, workdir: Path, port: int | None = None, tls: dict | None = None):
        self.workdir = Path(workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.port = port or free_port()
        self.tls = tls
        self.proc: subprocess.Popen | None = None
        self.frozen = False
        self.log = self.workdir / f"mosquitto-{self.port}.log"
        self.conf = self.workdir / f"mosquitto-{self.port}.conf"
        lines = [f"listener {self.port} 127.0.0.1", "allow_anonymous true",
                 "persistence false", "log_dest stderr", "log_type error",
                 "log_type warning"]
        if os.geteuid() == 0:
            lines.append("user root")  # keep access to the root-only temporary directory
        if tls:
            lines += [f"cafile {tls['ca']}", f"certfile {tls['cert']}",
                      f"keyfile {tls['key']}"]
        self.conf.write_text("\n".join(lines) + "\n")

    @property
    def url(self) -> str:
        return f"{'mqtts' if self.tls else 'mqtt'}://127.0.0.1:{self.port}"

    def start(self) -> Mosquitto:
        assert self.proc is None or self.proc.poll() is not None, "already running"
        with open(self.log, "ab") as log:
            self.proc = subprocess.Popen([mosquitto_binary(), "-c", str(self.conf)],
                                         stdout=log, stderr=log)
        deadline = time.monotonic() + DEADLINE_S
        while True:
            if self.proc.poll() is not None:
                raise AssertionError(f"mosquitto exited with {self.proc.returncode}: "
                                     f"{self.log.read_text(errors='replace')[-2000:]}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=1.0):
                    return self
            except OSError:
                if time.monotonic() > deadline:
                    self.kill()
                    raise AssertionError(f"mosquitto did not listen on {self.port} within "
                                         f"{DEADLINE_S} s") from None
                time.sleep(0.05)

    def kill(self) -> None:
        """SIGKILL: connections die without a DISCONNECT (as in a crash)."""
        if self.proc is not None and self.proc.poll() is None:
            if self.frozen:
                self.proc.send_signal(signal.SIGCONT)
            self.proc.kill()
            self.proc.wait(timeout=DEADLINE_S)
        self.frozen = False

    def freeze(self) -> None:
        """SIGSTOP: the broker stops reading (a stalled broker; the kernel still accepts)."""
        self.proc.send_signal(signal.SIGSTOP)
        self.frozen = True

    def thaw(self) -> None:
        self.proc.send_signal(signal.SIGCONT)
        self.frozen = False


@pytest.fixture(scope="session")
def mosquitto(tmp_path_factory):
    broker = Mosquitto(tmp_path_factory.mktemp("mosquitto")).start()
    yield broker
    broker.kill()


@pytest.fixture
def mosquitto_factory(tmp_path):
    started: list[Mosquitto] = []

    def make(port: int | None = None, tls: dict | None = None) -> Mosquitto:
        broker = Mosquitto(tmp_path, port, tls)
        started.append(broker)
        return broker

    yield make
    for broker in started:
        broker.kill()


@pytest.fixture
def amqtt():
    # one broker per test: amqtt 0.12 iterates its subscription table in one client's
    # session handler while another session changes it ("dictionary changed size during
    # iteration", seen once in CI under load), so sessions of earlier tests must not share
    # it; the embedded broker starts in well under a second
    broker = EmbeddedBroker().start()
    yield broker
    broker.stop()


@pytest.fixture(params=["mosquitto", "amqtt"])
def broker_url(request) -> str:
    """URL of a running broker: the session's mosquitto, then the embedded amqtt."""
    return request.getfixturevalue(request.param).url


@pytest.fixture(scope="session")
def depth_sample():
    """(frame, config): a 160 x 120 depth frame of a few boxes seen from a pitched, yawed
    camera mounted ahead of the body origin; part of the image sees nothing (NaN)."""
    parts = []
    for centre, extents in (((6.0, 0.0, 1.5), (1.0, 4.0, 3.0)),
                            ((4.0, 2.5, 1.0), (1.0, 1.0, 2.0)),
                            ((8.0, -3.0, 2.0), (2.0, 2.0, 4.0))):
        box = trimesh.creation.box(extents=extents)
        box.apply_translation(centre)
        parts.append(box)
    mesh = trimesh.util.concatenate(parts)
    config = CameraConfig(mount_position_body=(0.1, 0.0, 0.05), mount_pitch_rad=0.1,
                          max_range_m=10.0).subsampled(4)
    camera = DepthCamera(config, mesh)
    yaw = 0.2
    q = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
    frame = camera.capture(12_345_678, (0.5, -0.2, 1.2), q)
    assert (config.width, config.height) == (160, 120)
    valid = np.isfinite(frame.depth)
    assert 0 < valid.sum() < valid.size, "the sample should mix returns and no returns"
    return frame, config
