"""The hostile campaign: planted checkpoints, hostile output folders, special files,
cases that ask for the machine, hostile adapters, concurrent runs, hostile names and
damaged tables, each against a checkout's ``truestep``, every attack counted as held or
broken.

    python tools/campaigns/hostile_campaign.py [--repo PATH] [--python PATH] [--only 1,2,...]
        [--json FILE] [--work DIR]

``--repo`` is the checkout to attack (default: this one) and ``--python`` an interpreter
of a venv where it is installed (default: ``PATH/.venv/bin/python``): run it once on the
code before a change and once after, with the same command. Every input an attack needs
(case files, tables, adapters) is made here, the same for both, and every truestep
command runs in a process of its own, niced, in its own session, with its address space
capped and a wall timeout.

The attacks (``hostile_attacks/``, a module per group) are grouped by the findings
of issue 20 (:data:`~hostile_attacks.common.GROUPS`): 1 planted checkpoints under
``--resume``, 2 hostile ``--out`` folders, 3 special files where a file is read, 4 case
files that raise their own limits, 5 hostile adapters (``hostile_attacks/
hostile_adapters.py``), 6 two runs on one ``--out``, 7 hostile names and texts in every
output, 8 damaged tables, a full disk and gates that the API and the command line judge
differently; and 9 the failures of issue 37 (round three: plugins that end their process,
files beside ``--out`` that are the user's, what ``run`` writes that ``gate`` must read),
each run through ``python -m truestep``, the command as a user starts it. An attack
*holds* when truestep does what the issue asks (refuses with exit 2 and one line, ignores
the planted data, contains the adapter, escapes the text ...) and *breaks* otherwise;
what it checks is in each attack's docstring and its verdict's note.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hostile_attacks import BY_GROUP
from hostile_attacks.common import GROUPS, HERE, Campaign, Target


@dataclass
class Summary:
    target: dict[str, str]
    command: str
    counts: dict[int, dict[str, int]] = field(default_factory=dict)
    verdicts: list[dict] = field(default_factory=list)
    seconds: float = 0.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repo", type=Path, default=HERE.parents[1], help="checkout to attack")
    parser.add_argument("--python", type=Path, default=None, help="interpreter that imports that checkout")
    parser.add_argument("--only", default="", help="groups to run, comma-separated (default all)")
    parser.add_argument("--json", type=Path, default=None, help="write the summary here")
    parser.add_argument("--work", type=Path, default=None, help="keep the generated files here")
    args = parser.parse_args(argv)
    target = Target.of(args.repo, args.python)
    work = args.work or Path(tempfile.mkdtemp(prefix="hostile-campaign-"))
    campaign = Campaign(target, work)
    only = {int(x) for x in args.only.split(",") if x.strip()} or set(GROUPS)
    print(
        f"attacking {target.repo} ({target.commit}) with {target.python}; files in {work}",
        file=sys.stderr,
        flush=True,
    )
    started = time.perf_counter()
    for group, fns in BY_GROUP.items():
        if group in only:
            print(f"{group}. {GROUPS[group]}", file=sys.stderr, flush=True)
            for fn in fns:
                campaign.attack(group, fn)
    summary = Summary(
        {k: str(v) for k, v in asdict(target).items()},
        " ".join([Path(sys.executable).name, *sys.argv]),
        seconds=round(time.perf_counter() - started, 1),
    )
    for v in campaign.verdicts:
        counts = summary.counts.setdefault(v.group, {"tried": 0, "held": 0, "broken": 0})
        counts["tried"] += 1
        counts["held" if v.held else "broken"] += 1
    summary.verdicts = [asdict(v) for v in campaign.verdicts]
    print(f"target {target.repo} at {target.commit}")
    print("| # | finding | tried | held | broken |")
    print("|---|---|---|---|---|")
    for group, counts in sorted(summary.counts.items()):
        print(f"| {group} | {GROUPS[group]} | {counts['tried']} | {counts['held']} | {counts['broken']} |")
    broken = [v for v in campaign.verdicts if not v.held]
    for v in broken:
        print(f"BROKEN [{v.group}] {v.name}: {v.note}")
    print(f"{summary.seconds:.0f} s")
    if args.json:
        args.json.write_text(json.dumps(asdict(summary), indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
