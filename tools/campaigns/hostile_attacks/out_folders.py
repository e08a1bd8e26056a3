"""Hostile ``--out`` folders: only a report truestep wrote is replaced."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import time
from pathlib import Path

from hostile_attacks.common import (
    RUN_TIMEOUT,
    Campaign,
    refused,
    snapshot,
    user_folder,
)


def untouched_refusal(
    c: Campaign,
    where: Path,
    out: str,
    folder: Path,
    *,
    cwd: Path | None = None,
    env: dict[str, str] | None = None,
) -> tuple[bool, str]:
    before = snapshot(folder)
    result = c.quick_run(cwd or where, out, cases="free-fall", env=env)
    after = snapshot(folder)
    if after != before:
        lost = sorted(set(before) - set(after))
        changed = sorted(k for k in set(before) & set(after) if before[k] != after[k])
        return False, f"{result.why()}; lost {lost[:4]}, changed {changed[:4]}"
    return refused(result)


def attack_out_is_a_folder_of_other_files(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--out`` names a folder of someone's files (some named like a report's)."""
    folder = user_folder(where / "mine")
    return untouched_refusal(c, where, "mine", folder)


def attack_out_is_the_current_directory(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--out .`` in a folder of someone's files."""
    folder = user_folder(where / "project")
    return untouched_refusal(c, where, ".", folder, cwd=folder)


def attack_out_is_the_home_directory(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--out ~`` (as the shell expands it) on a home directory."""
    home = user_folder(where / "home")
    (home / ".bashrc").write_text("export X=1\n")
    return untouched_refusal(c, where, str(home), home, env=c.env(HOME=str(home)))


def attack_out_is_a_link_to_other_files(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--out`` is a symbolic link to a folder of someone's files."""
    folder = user_folder(where / "mine")
    (where / "link").symlink_to(folder)
    return untouched_refusal(c, where, "link", folder)


def attack_out_is_a_file(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--out`` names a file."""
    (where / "file").write_text("mine\n")
    return untouched_refusal(c, where, "file", where / "file")


def attack_report_holding_a_link_elsewhere(c: Campaign, where: Path) -> tuple[bool, str]:
    """A report folder whose ``figures`` was replaced by a link to someone's pictures."""
    shutil.copytree(c.base_report(), where / "rep")
    pictures = user_folder(where / "pictures")
    shutil.rmtree(where / "rep" / "figures")
    (where / "rep" / "figures").symlink_to(pictures)
    before = snapshot(pictures)
    result = c.quick_run(where, "rep", cases="free-fall")
    if snapshot(pictures) != before:
        return False, f"the linked folder changed: {result.why()}"
    if result.code == 0:
        return not (where / "rep" / "figures").is_symlink(), f"ran; {result.why()}"
    return refused(result)


def attack_planted_scratch_folder_beside_out(c: Campaign, where: Path) -> tuple[bool, str]:
    """A link named like the folder a killed run moved its old report to
    (``.rep.old-PID`` of a pid that is gone), leading to someone's files, with ``rep``
    absent: the link is never followed and the files are untouched."""
    folder = user_folder(where / "mine")
    before = snapshot(folder)
    (where / ".rep.old-999999").symlink_to(folder)
    result = c.quick_run(where, "rep", cases="free-fall")
    if snapshot(folder) != before:
        return False, f"the linked folder changed: {result.why()}"
    real = (where / "rep").is_dir() and not (where / "rep").is_symlink()
    return result.code == 0 and real, f"rep is a real folder: {real}; {result.why()}"


def attack_modes_and_owners_come_from_the_old_report(c: Campaign, where: Path) -> tuple[bool, str]:
    """A report folder made world-writable, its figures owned by another user: the new
    report's folder has this process's mode (umask) and owner."""
    rep = where / "rep"
    shutil.copytree(c.base_report(), rep)
    os.chmod(rep, 0o777)
    if os.geteuid() == 0:
        os.chown(rep / "figures", 65534, 65534)
    result = c.quick_run(where, "rep", cases="free-fall")
    if result.code != 0:
        return result.clean_refusal, result.why()
    mode = stat.S_IMODE(os.stat(rep).st_mode)
    owners = {os.stat(p).st_uid for p in [rep, *rep.rglob("*")]}
    umask = os.umask(0)
    os.umask(umask)
    ok = mode == 0o777 & ~umask and owners == {os.geteuid()}
    return ok, f"mode {oct(mode)} (umask gives {oct(0o777 & ~umask)}), owners {sorted(owners)}"


def attack_a_process_writing_into_out(c: Campaign, where: Path) -> tuple[bool, str]:
    """Another process writes files into the folder while truestep runs on it."""
    folder = where / "busy"
    folder.mkdir()
    writer = subprocess.Popen(
        [
            sys.executable,
            "-c",
            (
                "import sys, time, pathlib\n"
                "d = pathlib.Path(sys.argv[1])\n"
                "for i in range(100000):\n"
                "    (d / f'part-{i:05d}.dat').write_text(str(i))\n"
                "    time.sleep(0.005)\n"
            ),
            str(folder),
        ],
        start_new_session=True,
    )
    try:
        time.sleep(0.5)
        result = c.quick_run(where, "busy", cases="free-fall")
    finally:
        writer.kill()
        writer.wait()
    written = sorted(folder.glob("part-*.dat")) if folder.is_dir() else []
    highest = int(written[-1].stem.split("-")[1]) + 1 if written else 0
    lost = highest - len(written)
    if lost:
        return False, f"{lost} of the writer's {highest} files lost; {result.why()}"
    return refused(result)


def attack_figures_command_into_a_folder_of_other_files(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep figures --out`` on a folder of someone's files."""
    folder = user_folder(where / "mine")
    before = snapshot(folder)
    result = c.truestep(["figures", "--out", "mine"], where, timeout=RUN_TIMEOUT)
    if snapshot(folder) != before:
        return False, f"the folder changed: {result.why()}"
    return refused(result)


def attack_bench_command_into_a_folder_of_other_files(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep bench --out`` on a folder of someone's files (a tiny bench)."""
    folder = user_folder(where / "mine")
    before = snapshot(folder)
    result = c.truestep(
        ["bench", "--engines", "reference", "--sizes", "100", "--budget", "1", "--out", "mine"],
        where,
        timeout=RUN_TIMEOUT,
    )
    if snapshot(folder) != before:
        return False, f"the folder changed: {result.why()}"
    return refused(result)


ATTACKS = [
    attack_out_is_a_folder_of_other_files,
    attack_out_is_the_current_directory,
    attack_out_is_the_home_directory,
    attack_out_is_a_link_to_other_files,
    attack_out_is_a_file,
    attack_report_holding_a_link_elsewhere,
    attack_planted_scratch_folder_beside_out,
    attack_modes_and_owners_come_from_the_old_report,
    attack_a_process_writing_into_out,
    attack_figures_command_into_a_folder_of_other_files,
    attack_bench_command_into_a_folder_of_other_files,
]
