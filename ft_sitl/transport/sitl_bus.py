"""The simulator's side of the MQTT bus: one vehicle's telemetry, events and depth frames.

:class:`SitlBus` is serviced after every chunk of simulated time (by the SITL server or a
trial's judge). It publishes through a :class:`~ft_sitl.bus.publisher.BusPublisher`, which
never blocks: a slow, absent or restarting broker costs dropped messages (counted), never
simulation time. What it publishes (docs/mqtt.md):

* telemetry at ``telemetry_rate_hz`` of simulated time (default 50; clients change it with a
  config request): world ENU pose and velocity, attitude, body rates, motor outputs
  (rotor speed / maximum);
* events: armed / disarmed, mode changes (PX4 names), collisions with what was hit and the
  speed (``mover_collision`` for a moving obstacle), and what its owner adds (trial start
  and end);
* the moving obstacles of the vehicle's world (the collision guard's movers, as the guard
  checks them: scenarios.movers), with every telemetry sample: name, shape, size, centre,
  heading and velocity;
* depth frames from the vehicle's depth camera at the camera's rate, once a client asked
  for them (config ``{"depth": true}``), rendered from the scenario mesh and the movers
  where they are at the frame's simulated time.
"""

from __future__ import annotations

import logging
import threading

import numpy as np

from ft_sitl.bus.codec import EventType, MoverStates, Telemetry
from ft_sitl.bus.publisher import BusPublisher
from ft_sitl.bus.ratelimit import RateGate
from ft_sitl.mover_kinds import SIZE_FIELDS
from ft_sitl.scenarios.camera import DepthCamera, camera_config
from ft_sitl.sim.guard import GuardEventKind

log = logging.getLogger("ft_sitl.bus")


class SitlBus:
    def __init__(self, publisher_factory, fleet, index: int = 0, *, scenario=None,
                 camera=None, telemetry_rate_hz: float = 50.0, rng=None):

        self.fleet, self.i = fleet, index
        self._lock = threading.Lock()
        self._rate = float(telemetry_rate_hz)
        self._gate = RateGate(self._rate)
        self._want_depth = False
        self._want_points = False
        self.camera = None
        self.camera_config = camera
        if scenario is not None and camera is not None:

            self.camera = DepthCamera(camera, scenario.mesh)
        # the depth noise's stream (a trial's plan gives its own; a served fleet's is fixed)
        self._rng = rng if rng is not None else np.random.default_rng(
            np.random.SeedSequence([0, 7]))
        self._next_frame_us = 0
        self._armed = None
        self._mode = None
        self._events_seen = 0
        self._fence_seen = 0
        self._movers = None  # the movers described in _mover_static
        self._mover_static: list[dict] = []
        self.frames_rendered = 0
        self.pub = publisher_factory(self._on_config)
        self.pub.start()

    # --- requests from clients (bus thread) ----------------------------------------------
    def _on_config(self, cfg: dict) -> None:
        with self._lock:
            if "telemetry_rate_hz" in cfg:
                self._rate = float(cfg["telemetry_rate_hz"])
                self._gate = RateGate(self._rate)
            if "depth" in cfg:
                self._want_depth = bool(cfg["depth"])
            if "points" in cfg:
                self._want_points = bool(cfg["points"])
        if (self._want_depth or self._want_points) and self.camera is None:
            log.warning("vehicle %s: depth frames requested, but this simulator has no "
                        "scenario/camera", self.pub.vehicle)

    # --- publishing (simulation thread) -----------------------------------------------------
    def event(self, event_type: str, **fields) -> None:
        self.pub.publish_event(event_type, int(self.fleet.time_us), **fields)

    def service(self) -> None:
        fleet, i = self.fleet, self.i
        t_us = int(fleet.time_us)
        cmd = fleet.commanders[i]
        if cmd.armed != self._armed:
            if self._armed is not None or cmd.armed:
                self.event(EventType.ARMED if cmd.armed else EventType.DISARMED)
            self._armed = cmd.armed
        mode = cmd.mode_name
        if mode != self._mode:
            self.event(EventType.MODE, mode=mode)
            self._mode = mode
        breaches = cmd.fence_events
        for _t_us, reason, action in breaches[self._fence_seen:]:
            self.event(EventType.GEOFENCE, reason=reason, action=action)
        self._fence_seen = len(breaches)
        events = fleet.events
        for ev in events[self._events_seen:]:
            if ev.vehicle == i and ev.kind in (GuardEventKind.COLLISION,
                                               GuardEventKind.MOVER_COLLISION):
                self.event(EventType.MOVER_COLLISION if ev.kind ==
                           GuardEventKind.MOVER_COLLISION else EventType.COLLISION,
                           object=str(ev.what), speed_m_s=float(ev.speed_m_s))
        self._events_seen = len(events)
        with self._lock:
            gate = self._gate
            want_frames = self._want_depth or self._want_points
        guard = fleet.guard
        movers = guard.movers if guard is not None else None
        if gate.take(t_us):
            if movers is not None:
                self.pub.publish_movers(self.mover_states(movers, t_us))
            sim = fleet.sim
            w = sim.rotor_speeds(i) / sim.platforms[i].rotor_speed_max_rad_s
            self.pub.publish_telemetry(Telemetry(
                time_usec=t_us, p_world_m=tuple(sim.position(i)),
                v_world_m_s=tuple(sim.velocity(i)), q_world_body=tuple(sim.attitude(i)),
                w_body_rad_s=tuple(sim.body_rates(i)),
                motors=tuple(float(min(max(v, 0.0), 1.0)) for v in w),
                wind_world_m_s=tuple(fleet.sim.wind_velocity(i))))
        if want_frames and self.camera is not None and t_us >= self._next_frame_us:
            period = round(1e6 / self.camera_config.rate_hz)
            self._next_frame_us = (t_us // period + 1) * period
            frame = self.camera.capture(t_us, fleet.sim.position(i), fleet.sim.attitude(i),
                                        rng=self._rng, movers=movers, movers_time_us=t_us)
            self.frames_rendered += 1
            if self._want_depth:
                self.pub.publish_depth(frame, self.camera_config)
            if self._want_points:
                self.pub.publish_points(frame, self.camera_config)

    def mover_states(self, movers, t_us: int) -> MoverStates:
        """The bus payload of ``movers`` (scenarios.movers.Movers) at simulated time t_us."""
        if movers is not self._movers:  # names, shapes and sizes: once per field
            self._movers = movers
            self._mover_static = [{k: d[k] for k in ("name", "shape", *SIZE_FIELDS[d["shape"]])}
                                  for d in movers.describe()]
        poses, vel = movers.poses(t_us), movers.velocities(t_us)
        return MoverStates(t_us, [
            {**st, "p_world_m": tuple(poses[j, :3].tolist()), "heading_rad": float(poses[j, 3]),
             "v_world_m_s": tuple(vel[j].tolist())} for j, st in enumerate(self._mover_static)])

    def stats(self):
        return self.pub.stats()

    def close(self) -> None:
        self.pub.close()


def fleet_buses(opts, fleet, base_instance: int = 0, *, scenario=None,
                camera: str = "benchmark", telemetry_rate_hz: float = 50.0,
                connect_timeout_s: float = 10.0) -> tuple[list[SitlBus], bool]:
    """The MQTT bus of a served fleet: one :class:`SitlBus` per vehicle on the broker
    ``opts`` (:class:`~ft_sitl.bus.options.BrokerOptions`), vehicle ids ``base_instance +
    i``; depth frames from ``camera`` ("benchmark", "d435" or "none") when flying in a
    ``scenario``. Waits up to ``connect_timeout_s`` so publishing starts connected (later
    outages only cost dropped messages, counted); returns (buses, all connected)."""
    cam = None
    if scenario is not None and camera != "none":
        cam = camera_config(camera, None, None, None)
    buses = []
    for i in range(fleet.n):
        vid = str(base_instance + i)
        buses.append(SitlBus(lambda on_config, vid=vid: BusPublisher(opts, vid,
                                                                      on_config=on_config),
                             fleet, i, scenario=scenario, camera=cam,
                             telemetry_rate_hz=telemetry_rate_hz))
    connected = all(b.pub.wait_connected(connect_timeout_s) for b in buses)
    return buses, connected
