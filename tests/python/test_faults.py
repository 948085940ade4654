"""Faults during a run (issue 21), as a user meets them: the process killed at a random moment
(SIGKILL) then --resume'd, the output folder's disk full, a NaN in the state. Each must leave every
file already written valid, and the first two must end as an uninterrupted run would."""

from __future__ import annotations

import hashlib
import math
import os
import random
import resource
import signal
import struct
import subprocess
import time
from pathlib import Path

import pytest

from test_pnet_cli import PNET, TINY, frame_data, pnet

SEAL = b"PNETSHA2"


def assert_frames_valid(out: Path):
    """Every frame file is whole: a PLY with its full payload, a PNG with its end chunk."""
    for ply in out.glob("frame_*.ply"):
        data = ply.read_bytes()
        head, _, body = data.partition(b"end_header\n")
        n = int([l for l in head.decode().splitlines() if l.startswith("element vertex")][0].split()[2])
        props = sum(1 for l in head.decode().splitlines() if l.startswith("property double"))
        assert len(body) == n * props * 8, f"{ply.name}: {len(body)} bytes of payload"
    for png in out.glob("frame_*.png"):
        assert png.read_bytes().endswith(b"\x00\x00\x00\x00IEND\xaeB`\x82"), f"{png.name}: no IEND chunk"


def frame_bytes(out: Path) -> dict:
    """Every frame's bytes but the id of the run that wrote it (the runs compared are different runs)."""
    return {p.name: frame_data(p) for p in sorted(out.glob("frame_*.ply"))}


RUN = ["--integrator", "explicit", "--dt", "2e-5", "--frames", "10", "--checkpoint-every", "1", "--threads", "1"]


def test_sigkill_at_random_moments_then_resume_equals_an_uninterrupted_run(tmp_path):
    scene = TINY / "sand_column_2d.json"
    reference = tmp_path / "reference"
    started = time.monotonic()
    r = pnet("simulate", scene, *RUN, "--out", reference)
    assert r.returncode == 0, r.stderr
    duration = time.monotonic() - started
    expected = frame_bytes(reference)
    rng = random.Random(2109)
    for attempt in range(3):
        out = tmp_path / f"killed_{attempt}"
        process = subprocess.Popen([str(PNET), "simulate", str(scene), *RUN, "--out", str(out)],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(rng.uniform(0.2, 0.9) * duration)
        process.send_signal(signal.SIGKILL)
        process.wait()
        assert_frames_valid(out)  # nothing half-written under a frame's name
        r = pnet("simulate", scene, *RUN, "--out", out, "--resume")
        if r.returncode == 2 and "no checkpoint" in r.stderr:  # killed before the first checkpoint
            r = pnet("simulate", scene, *RUN, "--out", out, "--overwrite")
        assert r.returncode == 0, r.stderr
        assert frame_bytes(out) == expected, f"attempt {attempt}: frames differ from the uninterrupted run"
        assert not list(out.glob("*.tmp.*")), "temporary files of the killed run left behind"


def _mount_tmpfs(path: Path, size: str) -> bool:
    path.mkdir()
    try:
        return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                              capture_output=True).returncode == 0
    except OSError:  # no mount program
        return False


def test_full_disk_stops_with_a_clear_message_keeping_written_frames(tmp_path):
    """A 600 KiB tmpfs as the output folder (a frame of the tiny scene is ~20 KiB with its PNG and
    checkpoint): the run must stop with exit 1 naming the file it could not write, and every frame
    already there must be whole. Without permission to mount (no root), the same write failure is
    made with a file-size limit (RLIMIT_FSIZE, EFBIG instead of ENOSPC)."""
    out = tmp_path / "disk"
    mounted = _mount_tmpfs(out, "600k")
    try:
        def limit():
            if not mounted:
                signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
                resource.setrlimit(resource.RLIMIT_FSIZE, (60_000, 60_000))
        r = subprocess.run([str(PNET), "simulate", str(TINY / "sand_column_2d.json"), "--integrator", "explicit",
                            "--frames", "200", "--out", str(out)], capture_output=True, text=True, timeout=300,
                           preexec_fn=limit)
        assert r.returncode == 1, (mounted, r.returncode, r.stderr[-500:])
        message = r.stderr.lower()
        assert ("no space left on device" in message or "file too large" in message), r.stderr[-500:]
        assert str(out) in r.stderr, "the message names the file"
        assert_frames_valid(out)
        assert len(list(out.glob("frame_*.ply"))) >= 2, "frames were written before the disk filled"
        assert not list(out.glob("*.tmp.*")), "a failed write leaves no temporary file"
    finally:
        if mounted:
            subprocess.run(["umount", str(out)], check=True)


def _reseal(data: bytes) -> bytes:
    payload = data[:-72]
    assert data[-72:-64] == SEAL
    return payload + SEAL + hashlib.sha256(payload).hexdigest().encode()


@pytest.mark.parametrize("field, offset_arrays", [("position", 0), ("velocity", 1)])
def test_nan_in_the_state_is_refused_naming_the_particle(tmp_path, field, offset_arrays):
    """A checkpoint whose state holds a NaN (resealed, as a bug upstream would write it): --resume
    refuses it naming the particle and the field, and the frames already written stay as they were."""
    out = tmp_path / "run"
    r = pnet("simulate", TINY / "sand_column_2d.json", "--integrator", "explicit", "--frames", 2,
             "--checkpoint-every", 1, "--out", out)
    assert r.returncode == 0, r.stderr
    before = frame_bytes(out)
    path = out / "checkpoint.bin"
    data = bytearray(path.read_bytes())
    dim, n = struct.unpack_from("<qq", data, 8)
    header = 8 + 4 * 8 + 8 + 64 + 16 + 8
    particle = 17
    at = header + offset_arrays * n * dim * 8 + particle * dim * 8 + 8  # its y component
    struct.pack_into("<d", data, at, math.nan)
    path.write_bytes(_reseal(bytes(data)))
    r = pnet("simulate", TINY / "sand_column_2d.json", "--integrator", "explicit", "--frames", 4, "--out", out,
             "--resume")
    assert r.returncode == 2, r.stderr
    assert f"particle {particle}" in r.stderr and field in r.stderr, r.stderr
    assert frame_bytes(out) == before
