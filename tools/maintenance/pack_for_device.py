"""Pack the Warp engines for the lent GPU machine, in parts its transfers can carry.

The GPU machine (the tool library's ``device`` README) runs Python 3.12 with numpy, scipy,
pandas, matplotlib, numba, tqdm and absl-py, and nothing can be installed there from the
network; each call carries at most 64 MiB of the working tree, and carried paths stay
there while the machine is warm (some 30 s between calls). Warp's wheel alone is some
149 MB. This script downloads the wheels the GPU checks need (``warp-lang`` and
``newton`` at the versions installed here; with ``--mujoco-warp``, MuJoCo Warp and MuJoCo
too) for Python 3.12 on x86-64 Linux, packs them into one tar file cut into parts of
``--part-mib`` MiB under ``.device/`` (which it adds to ``.git/info/exclude``), and prints
the calls that carry them, one part a call (each part as large as the 64 MiB leave beside
the checkout's tracked files, which travel with every call), the last one unpacking, installing them and
truestep (``pip install --no-index --no-deps``) and running ``benchmarks/gpu_checks.py``.

Usage: ``python tools/maintenance/pack_for_device.py [--mujoco-warp] [--part-mib N]``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tarfile
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FOLDER = ".device"
PLATFORMS = ("manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64")
WARP = ("warp-lang", "newton")
MUJOCO_WARP = ("mujoco-warp", "mujoco", "mujoco-core", "mujoco-studio", "glfw", "pyopengl", "etils")


def download(names: tuple[str, ...], into: Path) -> list[Path]:
    """Each package's wheel for Python 3.12 on x86-64 Linux, at the version installed here
    (any version where it is not), without its dependencies (listed in ``names``)."""
    pins = []
    for name in names:
        try:
            pins.append(f"{name}=={metadata.version(name)}")
        except metadata.PackageNotFoundError:
            pins.append(name)
    command = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:"]
    command += ["--python-version", "3.12", "--implementation", "cp", "-d", str(into)]
    for platform in PLATFORMS:
        command += ["--platform", platform]
    subprocess.run(command + pins, check=True)
    return sorted(into.glob("*.whl"))


def pack(wheels: list[Path], folder: Path, part_mib: int) -> list[Path]:
    """``wheels`` in one tar file under ``folder`` (``wheels/NAME.whl``), cut into parts of
    ``part_mib`` MiB (``part-00``, ``part-01``...); returns the parts."""
    whole = folder / "wheels.tar"
    with tarfile.open(whole, "w") as tar:
        for wheel in wheels:
            tar.add(wheel, arcname=f"wheels/{wheel.name}")
    parts = []
    size = part_mib * 2**20
    with whole.open("rb") as source:
        while chunk := source.read(size):
            part = folder / f"part-{len(parts):02d}"
            part.write_bytes(chunk)
            parts.append(part)
    whole.unlink()
    return parts


LIMIT_MIB = 64
"""What one call of the device tool carries: the tracked files, then the carried part."""


def room_mib() -> int:
    """MiB a part may take: :data:`LIMIT_MIB` less the checkout's tracked files and 2 MiB to spare."""
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    tracked = sum(
        (ROOT / name).stat().st_size for name in listed.decode().split("\0") if (ROOT / name).is_file()
    )
    return int(LIMIT_MIB - tracked / 2**20 - 2)


def ignore(folder: str) -> None:
    """Add ``/folder/`` to the checkout's ``.git/info/exclude`` (it must not be committed,
    and the device tool carries only ignored paths it is asked to)."""
    exclude = ROOT / ".git" / "info" / "exclude"
    lines = exclude.read_text().splitlines() if exclude.exists() else []
    if f"/{folder}/" not in lines:
        exclude.parent.mkdir(parents=True, exist_ok=True)
        exclude.write_text("\n".join([*lines, f"/{folder}/"]) + "\n")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--mujoco-warp", action="store_true", help="also MuJoCo Warp and MuJoCo (the twin rows)"
    )
    parser.add_argument(
        "--part-mib", type=int, help="MiB a part (default: what 64 MiB leave beside the checkout)"
    )
    args = parser.parse_args()
    folder = ROOT / FOLDER
    wheels_dir = folder / "download"
    wheels_dir.mkdir(parents=True, exist_ok=True)
    ignore(FOLDER)
    wheels = download(WARP + (MUJOCO_WARP if args.mujoco_warp else ()), wheels_dir)
    parts = pack(wheels, folder, args.part_mib or room_mib())
    for wheel in wheels:
        wheel.unlink()
    wheels_dir.rmdir()
    print(f"{len(wheels)} wheels in {len(parts)} parts under {FOLDER}/:")
    for k, part in enumerate(parts[:-1]):
        print(f"  call {k + 1}: run(carry=[{str(part.relative_to(ROOT))!r}], command='true')")
    last = parts[-1].relative_to(ROOT)
    print(
        f'  call {len(parts)}: run(carry=[{str(last)!r}], command="cat {FOLDER}/part-* | tar -x -C /tmp && '
        "python3 -m pip install --quiet --no-index --no-deps /tmp/wheels/*.whl && "
        "python3 -m pip install --quiet --no-index --no-deps --no-build-isolation -e . && "
        'python3 benchmarks/gpu_checks.py --out $OUT/gpu")'
    )
    print("Make the calls one after another (the machine keeps the parts while warm, some 30 s).")
    return 0


if __name__ == "__main__":
    sys.exit(main())
