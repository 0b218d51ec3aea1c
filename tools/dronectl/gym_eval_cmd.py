"""`dronectl gym-eval`: policies run in the Gymnasium environment `DroneInspect/Centring-v0`, success rates.

    dronectl gym-eval --policy latent,random,oracle --episodes 100 --seed 0

Every policy meets the same episodes (scenes, starts, phrasings). Success is "centred within ε per
simulator truth within the step budget", with its 95 % Wilson interval.
"""

from __future__ import annotations

import logging
import sys

from drone_inspect_core.files import write_json_atomic
from dronectl.options import CommandParser, at_least, new_file, seed_value


def main(argv: list[str]) -> int:
    parser = CommandParser(prog="dronectl gym-eval", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--policy", default="latent,random,oracle", help="comma-separated (default: %(default)s)"
    )
    parser.add_argument(
        "--episodes", type=at_least(1), default=100, help="episodes per policy (default: %(default)s)"
    )
    parser.add_argument(
        "--seed", type=seed_value, default=0, help="picks the episodes (default: %(default)s)"
    )
    parser.add_argument(
        "--max-steps", type=at_least(1), default=20, help="step budget (default: %(default)s)"
    )
    parser.add_argument("--moves", default="fixed", choices=("fixed", "constant"), help="move lengths")
    parser.add_argument(
        "--instructions", default="fixed", choices=("fixed", "train", "heldout"), help="phrasing corpus"
    )
    parser.add_argument("--checkpoint", help="latent planner checkpoint folder (default: the shipped one)")
    parser.add_argument("--json", type=new_file, help="write the summary and every episode here")
    args = parser.parse_args(argv)
    logging.getLogger().setLevel(logging.WARNING)
    try:
        from controller.evaluation.gym_policies import evaluate, format_table
    except ImportError as exc:
        print(f"dronectl gym-eval: {exc}", file=sys.stderr)
        return 2
    policies = [p.strip() for p in args.policy.split(",") if p.strip()]
    env_kwargs = {"max_steps": args.max_steps, "moves": args.moves, "instructions": args.instructions}
    try:
        result = evaluate(policies, args.episodes, args.seed, env_kwargs, args.checkpoint)
    except ValueError as exc:
        parser.error(str(exc))
    print(f"DroneInspect/Centring-v0: {args.episodes} episodes per policy, seed {args.seed}, {env_kwargs}")
    print(format_table(result, policies))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(args.json, result, indent=1)
        print(f"wrote {args.json}", file=sys.stderr)
    return 0
