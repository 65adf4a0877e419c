"""The parameter protocol as ArduPilot answers it (GCS_Param.cpp): ArduCopter's names
(:mod:`.params`), integers C-cast into PARAM_VALUE's float with their own type (INT8,
INT16, INT32), an unknown name or a NaN/inf value ignored without an answer. A value the
declaration refuses gets ArduPilot's "Param write denied" warning, the reason (name, value,
range) and the unchanged value echoed: ArduPilot itself stores an out-of-range value; ft-sitl
does not fly one (docs/mavlink.md, ArduCopter face)."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.params import ParamError
from ft_sitl.mavlink.ardupilot.params import AP_PARAMS
from ft_sitl.mavlink.outgoing import Outgoing
from ft_sitl.mavlink.parameters import PARAM_STREAM_CHUNK, Parameters, param_name

AP_NAMES = list(AP_PARAMS)
AP_INDEX = {n: k for k, n in enumerate(AP_NAMES)}


class ArduCopterParameters(Parameters):
    """One vehicle's ArduCopter parameters on the wire."""

    def value(self, name: str) -> apm.MAVLink_param_value_message:
        return apm.MAVLink_param_value_message(
            name.encode("ascii"), float(self.v.ap_params[name]), AP_PARAMS[name].ptype,
            len(AP_NAMES), AP_INDEX[name])

    def poll(self) -> list[Outgoing]:
        out = []
        for key, start in list(self._streams.items()):
            stop = min(start + PARAM_STREAM_CHUNK, len(AP_NAMES))
            out.extend(Outgoing(self.value(n), *key) for n in AP_NAMES[start:stop])
            if stop >= len(AP_NAMES):
                del self._streams[key]
            else:
                self._streams[key] = stop
        return out

    def on_request_read(self, m, link, peer, wall_us):
        if m.param_index >= 0:
            if m.param_index >= len(AP_NAMES):
                return []
            name = AP_NAMES[m.param_index]
        else:
            name = param_name(m.param_id)
            if name not in AP_PARAMS:
                return []
        return [Outgoing(self.value(name), link, peer)]

    def on_set(self, m, link, peer, wall_us):
        name = param_name(m.param_id)
        if name not in AP_PARAMS or not math.isfinite(m.param_value):
            return []  # ArduPilot: no answer
        try:
            self.set(name, float(m.param_value))
        except ParamError as exc:
            self.v.cmd.text(cm.Severity.WARNING, f"Param write denied ({name})")
            self.v.cmd.text(cm.Severity.INFO, str(exc))
        return [Outgoing(self.value(name))]

    def set(self, name: str, value) -> None:
        """Set one ArduCopter parameter (ParamError refuses it, nothing changed)."""
        self.v.ap_params.set(name, value)
        if self.v.ap_params.honoured(name):
            self.v.fleet.refresh_params()

    def file(self) -> bytes:
        """The parameters as a MAVProxy/Mission Planner .parm file (NAME,VALUE lines)."""
        return "".join(f"{n},{self.v.ap_params[n]:g}\n" for n in AP_NAMES).encode()
