"""`dronectl gym-eval`: policies run in the Gymnasium environment `DroneInspect/Centring-v0`, success rates.

    dronectl gym-eval --policy latent,random,oracle --episodes 100 --seed 0

Every policy meets the same episodes (scenes, starts, phrasings). Success is "centred within ε per
simulator truth within the step budget", with its 95 % Wilson interval.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="dronectl gym-eval", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--policy", default="latent,random,oracle", help="comma-separated (default: %(default)s)"
    )
    parser.add_argument(
        "--episodes", type=int, default=100, help="episodes per policy (default: %(default)s)"
    )
    parser.add_argument("--seed", type=int, default=0, help="picks the episodes (default: %(default)s)")
    parser.add_argument("--max-steps", type=int, default=20, help="step budget (default: %(default)s)")
    parser.add_argument("--moves", default="fixed", choices=("fixed", "constant"), help="move lengths")
    parser.add_argument(
        "--instructions", default="fixed", choices=("fixed", "train", "heldout"), help="phrasing corpus"
    )
    parser.add_argument("--checkpoint", help="latent planner checkpoint folder (default: the shipped one)")
    parser.add_argument("--json", type=Path, help="write the summary and every episode here")
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
        args.json.write_text(json.dumps(result, indent=1))
        print(f"wrote {args.json}", file=sys.stderr)
    return 0
