"""A small MAVLink shell (``SERIAL_CONTROL`` to the shell device), as PX4's nsh answers
MAVSDK's Shell plugin, QGroundControl's MAVLink console and MAVProxy's ``shell``.

It understands the commands scripts send to PX4 SITL most: ``ver`` / ``ver all``,
``param show|set|get NAME [VALUE]``, ``commander arm|disarm|takeoff|land|status|mode
NAME``, and ``help``. Everything else is answered ``nsh: NAME: command not found``, so a
client sees a clear refusal instead of silence. Output ends with PX4's ``nsh> `` prompt.
"""

from __future__ import annotations

from ft_sitl import __version__
from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.params import PARAMS, ParamError

PROMPT = "nsh> "
HELP = ("Builtin commands (ft-sitl's shell, a subset of PX4's nsh):\n"
        "  ver [all]\n  param show|get NAME\n  param set NAME VALUE\n"
        "  commander arm|disarm|takeoff|land|status|mode NAME\n  help\n")


class Shell:
    """One vehicle's shell: feed it bytes, read what it prints."""

    def __init__(self, agent):
        self.agent = agent
        self.pending = ""

    def feed(self, data: bytes) -> str:
        """Bytes from the client; the output of every complete line (with the prompt)."""
        self.pending += data.decode("ascii", "replace")
        out = []
        while "\n" in self.pending:
            line, self.pending = self.pending.split("\n", 1)
            line = line.strip("\r ").strip()
            if len(self.pending) > 4096:  # a client that never sends a newline
                self.pending = ""
            out.append(line + "\n" + self.run(line) + PROMPT)
        return "".join(out)

    def run(self, line: str) -> str:
        words = line.split()
        if not words:
            return ""
        cmd, args = words[0], words[1:]
        if cmd == "help":
            return HELP
        if cmd == "ver":
            return (f"HW arch: FT_SITL_DEFAULT\nFW version: 1.15.0 (ft-sitl {__version__})\n"
                    "OS: ft-sitl (Python)\n")
        if cmd == "param":
            return self._param(args)
        if cmd == "commander":
            return self._commander(args)
        return f"nsh: {cmd}: command not found\n"

    def _param(self, args) -> str:
        ps = self.agent.params
        if len(args) >= 2 and args[0] in ("show", "get"):
            name = args[1].upper()
            if name not in PARAMS:
                return f"param: parameter {name} not found\n"
            return f"{name}: {ps[name]}\n" if args[0] == "get" else \
                f"x + {name} [{list(PARAMS).index(name)}]: {ps[name]}\n"
        if len(args) == 3 and args[0] == "set":
            name = args[1].upper()
            try:
                value = float(args[2])
                if PARAMS.get(name) is not None and PARAMS[name].is_int:
                    value = int(value)
                self.agent.set_param(name, value)
            except (ValueError, ParamError) as exc:
                return f"param: {exc}\n"
            return f"{name}: {ps[name]}\n"
        return "usage: param show|get NAME | param set NAME VALUE\n"

    def _commander(self, args) -> str:
        c = self.agent.cmd
        if not args:
            return "usage: commander arm|disarm|takeoff|land|status|mode NAME\n"
        sub = args[0]
        if sub == "status":
            return (f"armed: {c.armed}\nmode: {c.mode_name}\n"
                    f"landed state: {c.landed_state.name}\n")
        if sub == "mode" and len(args) == 2:
            key = cm.MODE_BY_NAME.get(args[1].upper())
            if key is None:
                return f"commander: unknown mode {args[1]}\n"
            return f"{c.set_mode(*key).name}\n"
        actions = {"arm": c.arm, "disarm": c.disarm, "takeoff": c.takeoff, "land": c.land}
        if sub in actions:
            return f"{actions[sub]().name}\n"
        return f"commander: unknown command {sub}\n"
