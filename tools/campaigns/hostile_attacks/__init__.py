"""The attacks of ``tools/campaigns/hostile_campaign.py``, one module per finding of issue 20
(groups 1-8) and two for the fixes of issue 37 (group 9: ``round_three`` and
``round_three_more``, every failure of the issue that has an attack).

Each module's ``ATTACKS`` lists its attacks: functions ``(campaign, folder) -> (held,
note)`` whose docstring says what they do and what holding means."""

from hostile_attacks import (
    adapters,
    ceilings,
    checkpoints,
    names,
    one_run,
    out_folders,
    round_three,
    round_three_more,
    special_files,
    tables,
)

BY_GROUP = {
    1: checkpoints.ATTACKS,
    2: out_folders.ATTACKS,
    3: special_files.ATTACKS,
    4: ceilings.ATTACKS,
    5: adapters.ATTACKS,
    6: one_run.ATTACKS,
    7: names.ATTACKS,
    8: tables.ATTACKS,
    9: round_three.ATTACKS + round_three_more.ATTACKS,
}
"""Every attack, by the number of the finding it attacks (:data:`common.GROUPS`)."""
