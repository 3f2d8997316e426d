"""``egc-teleop replay`` on damaged logs (an outside check): whatever bytes of a log are
overwritten, the replay ends with exit 0 and a summary that says how much of the log it read,
or exit 2 and one line; never a traceback. A log the reader stops reading early (silently, or
with an error from the storage layer) is replayed as far as it could be read, with one line
saying what was not read and ``scans_unread`` / ``command_messages_unread`` in the summary."""

from __future__ import annotations

import contextlib
import io
import json
import shutil
import subprocess
import sys
from pathlib import Path

import egc_experiments.log_replay as log_replay
import numpy as np
import pytest
from egc_common.errors import UsageError
from egc_common.profiles import get_profile
from egc_robot.replay_core import Replayer

from tests.replay.logs import corridor_log

PINNED = ("scans", "commands", "changed", "max_cut_mps", "hold_s", "closest_m", "filter", "profile")
SCANS = 60  # corridor_log writes one command per scan
WALLS = tuple(np.linspace(2.5, 0.3, SCANS))


def run_replay(log: str) -> tuple[int, str, str]:
    """The replay engine in this process, as ``egc-teleop replay LOG`` runs it (the default
    filter and profile): 0, the summary as JSON and what it said on stderr; or 2, nothing and
    its UsageError, the one line the CLI prints after ``egc-teleop replay: error:`` (its real
    process: ``test_an_overflowing_record_length_in_a_real_process``). Any other exception
    escaping is the traceback a user would see."""
    err = io.StringIO()
    replayer = Replayer.for_filter("egc", get_profile("pioneer3dx"))
    with contextlib.redirect_stderr(err):
        try:
            summary = log_replay.replay(log_replay.log_file_in(Path(log)), replayer)
        except UsageError as exc:
            return 2, "", f"{err.getvalue()}{exc}\n"
    return 0, json.dumps(summary), err.getvalue()


def storage_file(log: Path) -> Path:
    (found,) = (p for p in log.iterdir() if p.suffix in (".mcap", ".db3"))
    return found


@pytest.fixture(scope="module", params=["mcap", "sqlite3"])
def clean_log(request, tmp_path_factory) -> tuple[Path, bytes]:
    log = corridor_log(tmp_path_factory.mktemp(request.param) / "log", request.param, WALLS)
    return log, storage_file(log).read_bytes()


def test_no_traceback_wherever_the_bytes_are_overwritten(clean_log, tmp_path):
    """64 bytes overwritten (0xff: huge lengths and offsets; 0x00; random) at 40 offsets spread
    over the storage file (MCAP: chunks, message indexes, summary; sqlite: pages, b-trees).
    Before the fix, some of these ended in OverflowError (MCAP) or apsw.CorruptError (sqlite)
    tracebacks out of the commands pass."""
    log, data = clean_log
    outcomes: dict[int, int] = {0: 0, 2: 0}
    short = 0
    for fill in ("ff", "00", "random"):
        for off in range(0, len(data) - 64, len(data) // 40):
            damaged = tmp_path / f"{fill}_{off}"
            shutil.copytree(log, damaged)
            bad = bytearray(data)
            if fill == "random":
                bad[off : off + 64] = np.random.default_rng(off).bytes(64)
            else:
                bad[off : off + 64] = bytes.fromhex(fill) * 64
            storage_file(damaged).write_bytes(bytes(bad))
            where = f"{fill} at {off}"
            try:
                code, out, err = run_replay(str(damaged))
            except Exception as exc:  # what a user would see as a traceback
                pytest.fail(f"{where}: {type(exc).__name__}: {exc}")
            assert code in (0, 2), where
            outcomes[code] += 1
            if code == 2:
                lines = err.strip().splitlines()
                assert out == "" and len(lines) == 1, (where, err)
                assert lines[0].startswith(f"{damaged}"), (where, err)  # names the log
                continue
            s = json.loads(out)
            assert all(k in s for k in PINNED), where
            # metadata.yaml (intact) declares 60 and 60: every scan and command is accounted for
            assert s["scans"] + s["scans_corrupt"] + s["scans_unread"] == SCANS, (where, s)
            commands = ("command_messages", "command_messages_corrupt", "command_messages_unread")
            assert sum(s[k] for k in commands) == SCANS, (where, s)
            if s["scans_unread"] or s["command_messages_unread"]:
                short += 1
                assert "the rest was not replayed" in err, (where, err)
            shutil.rmtree(damaged)
    # most damage is survivable; some of it stops the reader early
    assert outcomes[0] > outcomes[2] > 0 and short > 0, (outcomes, short)


def scramble(data: bytes, start: int, n: int = 2000) -> bytes:
    """The outside check's damage: ``n`` bytes from ``start`` mapped through x -> 7x + 13."""
    bad = bytearray(data)
    for i in range(start, start + n):
        bad[i] = (bad[i] * 7 + 13) & 255
    return bytes(bad)


def test_a_log_the_reader_stops_reading_early_says_so(tmp_path):
    """The outside check's corrupt.mcap: rosbags' MCAP reader stops at the damaged chunk
    without an error, while the file's statistics declare every message. Before the fix this
    replayed a third of the log with exit 0 and nothing to say it was incomplete."""
    log = corridor_log(tmp_path / "log", "mcap", WALLS)
    data = storage_file(log).read_bytes()
    mcap = tmp_path / "corrupt.mcap"  # alone: the counts come from the MCAP's own statistics
    mcap.write_bytes(scramble(data, len(data) // 3))
    code, out, err = run_replay(str(mcap))
    assert code == 0, err
    s = json.loads(out)
    assert 0 < s["scans"] < SCANS and 0 < s["command_messages"] < SCANS
    assert s["scans"] + s["scans_corrupt"] + s["scans_unread"] == SCANS
    assert s["command_messages"] + s["command_messages_unread"] == SCANS
    (line,) = (x for x in err.splitlines() if "not replayed" in x)
    read = s["scans"] + s["scans_corrupt"]
    assert line.startswith(
        f"egc-teleop replay: read {read} of the {SCANS} scans the log declares on '/scan'"
    ), line
    assert f"{s['command_messages']} of the {SCANS} messages on '/cmd_vel'" in line
    assert "the file is damaged after t = " in line and "of 5.9 s" in line, line
    assert s["read_error"] is None  # the reader raised nothing: only the counts tell
    # an intact log says nothing of the kind
    code, out, err = run_replay(str(log))
    s = json.loads(out)
    assert code == 0 and s["scans_unread"] == 0 and s["command_messages_unread"] == 0
    assert s["read_error"] is None and "not replayed" not in err


class FailingReader:
    """An AnyReader whose storage layer raises after ``good`` messages of a pass, as a damaged
    sqlite file does (apsw.CorruptError) or an MCAP with a huge record length (OverflowError)."""

    def __init__(self, reader, good: int, exc: Exception) -> None:
        self.reader, self.good, self.exc = reader, good, exc

    def __enter__(self):
        self.reader.__enter__()
        return self

    def __exit__(self, *exc):
        return self.reader.__exit__(*exc)

    def __getattr__(self, name):
        return getattr(self.reader, name)

    def messages(self, connections=()):
        for i, item in enumerate(self.reader.messages(connections=connections)):
            if i == self.good:
                raise self.exc
            yield item


@pytest.mark.parametrize(
    "exc", [OverflowError("Python int too large"), RuntimeError("database disk image is malformed")]
)
def test_a_reader_error_mid_log_keeps_what_was_read(tmp_path, monkeypatch, exc):
    log = corridor_log(tmp_path / "log", "sqlite3", WALLS)
    real = log_replay._reader
    monkeypatch.setattr(log_replay, "_reader", lambda path: FailingReader(real(path), 25, exc))
    code, out, err = run_replay(str(log))
    assert code == 0, err
    s = json.loads(out)
    assert s["scans"] == 25 and s["scans_unread"] == 35
    assert s["command_messages"] == 25 and s["command_messages_unread"] == 35
    assert s["read_error"] == f"{type(exc).__name__}: {exc}"
    (line,) = err.splitlines()
    assert line.startswith("egc-teleop replay: read 25 of the 60 scans the log declares on")
    assert f"(the reader: {type(exc).__name__}: {exc})" in line
    # nothing readable at all: a bad log, one line
    monkeypatch.setattr(log_replay, "_reader", lambda path: FailingReader(real(path), 0, exc))
    code, out, err = run_replay(str(log))
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert err.startswith(f"{log}: cannot read this log (")
    assert str(exc) in err


def test_an_overflowing_record_length_in_a_real_process(tmp_path):
    """0xff over an MCAP record length: rosbags seeks beyond a C ssize_t and raises
    OverflowError (the outside check's traceback). Found with rosbags itself, then replayed
    in a real process."""
    log = corridor_log(tmp_path / "log", "mcap", WALLS)
    data = storage_file(log).read_bytes()
    mcap = tmp_path / "bad.mcap"
    for off in range(0, len(data) - 64, 499):
        bad = bytearray(data)
        bad[off : off + 64] = b"\xff" * 64
        mcap.write_bytes(bytes(bad))
        try:
            with log_replay._reader(mcap) as reader:
                for _ in reader.messages():
                    pass
        except OverflowError:
            break
        except Exception:  # other damage: try the next offset
            continue
    else:
        pytest.fail("no offset makes rosbags raise OverflowError any more")
    proc = subprocess.run(
        [sys.executable, "-m", "egc_app.cli", "replay", str(mcap)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "Traceback" not in proc.stderr and proc.returncode in (0, 2), proc.stderr
    if proc.returncode == 2:
        assert proc.stdout == "" and proc.stderr.count("\n") == 1
    else:
        assert "not replayed" in proc.stderr and json.loads(proc.stdout)["read_error"]
