"""``ft-sitl train``: train a navigation policy (ft_sitl.gym.train) and write its file."""

from __future__ import annotations

import json

from ft_sitl.cli.common import CliError
from ft_sitl.gym.train import PRESET, TrainError, load_config, train


def cmd_train(args) -> int:
    overrides = {}
    if args.steps is not None:
        overrides["total_steps"] = int(args.steps)
    if args.seed is not None:
        overrides["seed"] = int(args.seed)
    try:
        cfg = load_config(args.config, overrides)
    except TrainError as exc:
        raise CliError(str(exc)) from None
    if args.check:
        print(f"# {args.config or PRESET}: valid")
        print(json.dumps({k: {kk: (list(vv) if isinstance(vv, tuple) else vv)
                              for kk, vv in v.items()} for k, v in cfg.items()},
                         indent=2, sort_keys=True))
        return 0
    try:
        path = train(cfg, args.out, progress=not args.quiet)
    except TrainError as exc:
        raise CliError(str(exc)) from None
    print(f"policy: {path}  (fly it: algorithms = [{{ name = \"learned\", params = "
          f"{{ policy = \"{path}\" }} }}])")
    return 0
