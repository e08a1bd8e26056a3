#!/usr/bin/env bash
# Mutation testing of the numpy physics and of the compiled kernels with cosmic-ray (see
# README.md beside this file; CONFIG=tools/campaigns/mutation/cosmic-ray-kernels.toml for the
# kernels' session).
#
#   bash tools/campaigns/mutation/run.sh all        # setup, init, before (BEFORE=1 exec), after (rerun)
#   bash tools/campaigns/mutation/run.sh setup      # a copy of HEAD in $MUT and a venv in $VENV
#   bash tools/campaigns/mutation/run.sh init       # the session: every mutant, filtered, sampled
#   bash tools/campaigns/mutation/run.sh exec       # run the pending mutants (nice 19, one worker)
#   BEFORE=1 bash tools/campaigns/mutation/run.sh exec   # the same without the kill tests ("before")
#   bash tools/campaigns/mutation/run.sh rerun OLD NEW  # NEW = OLD with its survivors run again
#   bash tools/campaigns/mutation/run.sh report [SESSION]
#   bash tools/campaigns/mutation/run.sh tests      # the per-mutant test command (cosmic-ray runs it)
#
# cosmic-ray mutates files in place, so everything runs in a copy of the committed tree
# ($MUT, default /tmp/truestep-mut), never in the checkout this script lives in.
# SAMPLE=k keeps every k-th mutant (default 40) in a fixed order (file, line, column,
# operator, occurrence), so two runs of one tree test the same mutants; OFFSET=o (default
# 0) keeps those at positions o, o + k, ... (so SAMPLE=40 with OFFSET=0 and 20 make up the
# SAMPLE=20 one).
set -euo pipefail
shopt -s nullglob

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../../.." && pwd)"
MUT="${MUT:-/tmp/truestep-mut}"
VENV="${VENV:-$MUT/.venv}"
SESSION="${SESSION:-$MUT/session.sqlite}"
SAMPLE="${SAMPLE:-40}"
OFFSET="${OFFSET:-0}"
CONFIG="${CONFIG:-tools/campaigns/mutation/cosmic-ray.toml}"  # cosmic-ray-kernels.toml: the kernels
export NUMBA_CACHE_DIR="${NUMBA_CACHE_DIR:-$MUT/.numba-cache}"

# The per-mutant tests: the kill tests first, then the existing tests that reach the numpy
# path of the mutated module (which file differs from the checksums init kept tells it).
# One slow convergence study is left out (17 s a run).
KILLS=(tests/reference_impl/test_forces.py tests/reference_impl/test_collisions.py tests/reference_impl/test_solvers.py tests/measures/test_metrics.py)
# The kill tests live in these files since 2026-12-02 (folded into the modules' unit tests):
# BEFORE=1 now leaves out only the files' place at the front, not the kill tests themselves.
if [ "${BEFORE:-0}" = 1 ]; then KILLS=(); fi
SOLVER_TESTS=(tests/reference_impl/test_tableaux.py tests/reference_impl/test_solvers.py tests/reference_impl/test_explicit_rk.py
              tests/measures/test_restitution.py)
FORCE_TESTS=(tests/reference_impl/test_forces.py tests/reference_impl/test_solvers.py tests/measures/test_properties.py)
COLLISION_TESTS=(tests/reference_impl/test_collisions.py tests/measures/test_properties.py
                 tests/measures/test_restitution.py)
METRIC_TESTS=(tests/measures/test_stability.py tests/measures/test_orders_in_run.py tests/measures/test_reference.py)
# The compiled path's kernels run as Python here (NUMBA_DISABLE_JIT=1): a mutant would
# otherwise recompile every loop the tests use, minutes a mutant. Its kernel tests, then
# the compiled path against the numpy oracle (less two 20 s scenes its other scenes and
# the tiling test cover: 1000 particles of rain, and a cloth beside the stiff cloth).
KERNEL_TESTS=(tests/reference_impl/test_reference_kernels.py tests/reference_impl/test_compiled.py)
KERNEL_DESELECT=(--deselect "tests/reference_impl/test_compiled.py::test_compiled_equals_numpy[particle-rain]"
                 --deselect "tests/reference_impl/test_compiled.py::test_compiled_equals_numpy[hanging-cloth]")
DESELECT=(--deselect tests/reference_impl/test_collisions.py::test_bounce_times_converge_at_first_order)
KERNEL_FILES=(reference_impl/forces_kernels.py reference_impl/collisions_kernels.py
              reference_impl/particles_kernels.py reference_impl/tiles.py
              reference_impl/integrate_kernels.py reference_impl/by_type.py
              reference_impl/fused_steps.py reference_impl/compiled.py)
# (reference_impl/solvers/any_method.py, a kernel file too, is among TARGETS by its folder:
# listed twice, a mutant of it would be seen as two changed files and run the wrong tests)
TARGETS=(reference_impl/solvers/*.py reference_impl/forces.py reference_impl/collisions.py
         truestep/measures/metrics.py "${KERNEL_FILES[@]}")

cmd="${1:-all}"
case "$cmd" in
setup)
    rm -rf "$MUT" && mkdir -p "$MUT"
    git -C "$REPO" archive HEAD | tar -x -C "$MUT"
    if [ ! -x "$VENV/bin/python" ]; then
        python3 -m venv "$VENV"
        "$VENV/bin/pip" install -q -e "$MUT[dev]" "cosmic-ray==8.7.0"
    fi
    # Warm numba's cache for the compiled path (not mutated) once, outside the timing.
    (cd "$MUT" && "$VENV/bin/python" -c "import truestep.reference_impl.compiled, truestep.reference_impl.forces as f; f.compile_springs()")
    ;;
init)
    cd "$MUT"
    rm -f "$SESSION"
    sha256sum "${TARGETS[@]}" > .pristine.sha256
    "$VENV/bin/cosmic-ray" init "$CONFIG" "$SESSION"
    "$VENV/bin/cr-filter-operators" "$SESSION" "$CONFIG"
    "$VENV/bin/python" - "$SESSION" "$SAMPLE" "$OFFSET" <<'EOF'
"""Keep every k-th mutant the operator filter left, in a fixed order; skip the rest."""
import sys

from cosmic_ray.work_db import WorkDB, use_db
from cosmic_ray.work_item import WorkerOutcome, WorkResult

session, k, offset = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
with use_db(session, WorkDB.Mode.open) as db:
    items = sorted(db.pending_work_items, key=lambda w: tuple(
        (str(m.module_path), m.start_pos, m.end_pos, m.operator_name, m.occurrence)
        for m in w.mutations))
    drop = [w.job_id for n, w in enumerate(items) if n % k != offset]
    db.set_multiple_results(drop, WorkResult(output=f"not sampled (every {k}th from {offset} kept)",
                                             worker_outcome=WorkerOutcome.SKIPPED))
    print(f"{len(items)} mutants after the operator filter, {len(items) - len(drop)} sampled")
EOF
    ;;
exec)
    cd "$MUT"
    PATH="$VENV/bin:$PATH" nice -n 19 "$VENV/bin/cosmic-ray" exec "$CONFIG" "$SESSION"
    ;;
rerun)
    old="$2" new="$3"
    cp "$old" "$new"
    "$VENV/bin/python" - "$new" <<'EOF'
"""Forget the results of the surviving mutants, so that exec runs them again."""
import sqlite3
import sys

db = sqlite3.connect(sys.argv[1])
n = db.execute("delete from work_results where test_outcome = 'SURVIVED'").rowcount
db.commit()
print(f"{n} survivors to run again")
EOF
    cd "$MUT"
    PATH="$VENV/bin:$PATH" nice -n 19 "$VENV/bin/cosmic-ray" exec "$CONFIG" "$new"
    ;;
report)
    cd "$MUT"
    "$VENV/bin/cr-report" --show-pending "${2:-$SESSION}" | tail -n 4
    "$VENV/bin/python" - "${2:-$SESSION}" <<'EOF'
"""Per module: killed / survived / timeout / incompetent among the sampled mutants."""
import collections
import sqlite3
import sys

db = sqlite3.connect(sys.argv[1])
rows = db.execute("""select s.module_path, r.worker_outcome, r.test_outcome, r.output
                     from mutation_specs s join work_results r using (job_id)""").fetchall()
counts = collections.defaultdict(collections.Counter)
for module, worker, test, output in rows:
    if worker == "SKIPPED":
        continue
    kind = ("incompetent" if test == "INCOMPETENT" or worker != "NORMAL" else
            "timeout" if test == "KILLED" and output == "timeout" else test.lower())
    counts[module][kind] += 1
print(f"{'module':42} {'killed':>7} {'survived':>9} {'timeout':>8} {'incompetent':>12} {'score':>7}")
total = collections.Counter()
for module in sorted(counts):
    c = counts[module]
    total.update(c)
    run = c["killed"] + c["survived"] + c["timeout"]
    print(f"{module:42} {c['killed']:7} {c['survived']:9} {c['timeout']:8} {c['incompetent']:12} "
          f"{(c['killed'] + c['timeout']) / max(run, 1):7.1%}")
run = total["killed"] + total["survived"] + total["timeout"]
print(f"{'total':42} {total['killed']:7} {total['survived']:9} {total['timeout']:8} "
      f"{total['incompetent']:12} {(total['killed'] + total['timeout']) / max(run, 1):7.1%}")
EOF
    ;;
tests)
    # Run from $MUT by cosmic-ray, once per mutant.
    changed="$(sha256sum --quiet -c .pristine.sha256 2>/dev/null | sed -n 's/: FAILED$//p')" || true
    case "$changed" in
        reference_impl/*_kernels.py|reference_impl/solvers/*_kernels.py|reference_impl/tiles.py|\
        reference_impl/by_type.py|reference_impl/fused_steps.py|reference_impl/compiled.py|\
        reference_impl/solvers/any_method.py)
            NUMBA_DISABLE_JIT=1 exec python -m pytest -x -q -p no:cacheprovider "${KERNEL_DESELECT[@]}" \
                "${KERNEL_TESTS[@]}" ;;
        reference_impl/solvers/*) tests=("${SOLVER_TESTS[@]}") ;;
        reference_impl/forces.py) tests=("${FORCE_TESTS[@]}") ;;
        reference_impl/collisions.py) tests=("${COLLISION_TESTS[@]}") ;;
        truestep/measures/metrics.py) tests=("${METRIC_TESTS[@]}") ;;
        *) tests=("${SOLVER_TESTS[@]}" "${FORCE_TESTS[@]}" "${COLLISION_TESTS[@]}" "${METRIC_TESTS[@]}") ;;
    esac
    exec python -m pytest -x -q -p no:cacheprovider "${DESELECT[@]}" "${KILLS[@]}" "${tests[@]}"
    ;;
all)
    "$0" setup && "$0" init
    cp "$SESSION" "$SESSION.init"
    BEFORE=1 "$0" exec && "$0" report && cp "$SESSION" "$MUT/before.sqlite"
    "$0" rerun "$MUT/before.sqlite" "$MUT/after.sqlite" && "$0" report "$MUT/after.sqlite"
    ;;
*)
    echo "usage: $0 [all|setup|init|exec|rerun OLD NEW|report [SESSION]|tests]" >&2
    exit 2
    ;;
esac
