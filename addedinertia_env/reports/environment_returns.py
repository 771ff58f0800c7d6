"""The reference returns of docs/ENVIRONMENT.md (zero, random and feedforward-PD policies).

    python -m addedinertia_env.reports.environment_returns --episodes 5 --out docs/ENVIRONMENT.md

runs :func:`addedinertia_env.envs.baselines.run` (env seeds 0-4, default options and weights),
prints its JSON and writes the table between the doc's ``baselines`` markers
(:func:`~addedinertia_env.reports.sections.replace_section`); ``make docs-environment``.
"""

from __future__ import annotations

import argparse
import json
import sys

from addedinertia_env.envs.baselines import BEGIN, END, POLICIES, run, table_block
from addedinertia_env.foundation.machine import machine_line
from addedinertia_env.reports.sections import replace_section


def main(argv: list[str] | None = None) -> int:
    """Regenerate the reference-returns table of ``--out`` (docs/ENVIRONMENT.md); ``argv`` as on the command line; returns 0."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--policies", nargs="+", default=list(POLICIES), choices=list(POLICIES))
    ap.add_argument("--out", default="docs/ENVIRONMENT.md", help="the doc holding the baselines markers")
    args = ap.parse_args(argv)
    if args.episodes < 1:
        ap.error("--episodes: expected at least 1")
    out = run(args.episodes, args.seed, args.policies)
    print(json.dumps(out, indent=1))
    command = f"python -m addedinertia_env.reports.environment_returns --episodes {args.episodes} --out {args.out}"
    if args.seed:
        command += f" --seed {args.seed}"
    replace_section(args.out, table_block(out, command, machine_line()), BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
