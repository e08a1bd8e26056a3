"""What the Newton adapter's one collision setting changes: the restitution sweep's drop
(``e`` = 0.8 asked, first three bounces) in every Newton method at 1/240 s and 1 ms, with
the ``soft_contact_gap = 1e4`` truestep sets and with Newton's default (issue 35,
finding 4: every engine setting truestep changes is listed with its measured effect on
``docs/engines/newton.md``)::

    python tools/experiments/newton_contact_gap.py
"""

from __future__ import annotations

import math

from truestep import numerics


def main() -> None:
    import argparse

    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    numerics.set_environment()
    import newton

    from truestep.execution.analyses import _bounce_rows

    original = newton.CollisionPipeline

    def with_default_gap(*args, **kwargs):
        kwargs.pop("soft_contact_gap", None)
        return original(*args, **kwargs)

    for label, pipeline in (("truestep's 1e4", original), ("Newton's default", with_default_gap)):
        newton.CollisionPipeline = pipeline
        for method in ("semi-implicit", "xpbd", "vbd"):
            for dt in (1 / 240, 1 / 1000):
                e = [r.get("e_measured", math.nan) for r in _bounce_rows("newton", method, 0.8, dt)]
                shown = ", ".join("-" if not math.isfinite(x) else f"{x:.3f}" for x in e)
                print(f"{label:17s} {method:13s} dt {dt:.5f}: e measured {shown}")
    newton.CollisionPipeline = original


if __name__ == "__main__":
    main()
