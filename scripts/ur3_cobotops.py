#!/usr/bin/env python3
"""Convert the UR3 CobotOps dataset into labelled fingertip traces (docs/recordings.md).

UR3 CobotOps (M. Tyrovolas, K. Aliev, D. Antonelli, C. Stylios; UCI Machine Learning
Repository, 2024, doi:10.24432/C5J891; CC BY 4.0) is a UR3 arm's controller log during a
pick-and-place program: once a second, the six joints' motor currents and speeds, the
gripper's current, the program's cycle count, and two flags, the controller's protective
stop and a lost grip. This script reads the dataset's spreadsheet (`.xlsx`, as published)
or a CSV export of it (`;` or `,` separated, decimal commas accepted) and writes one trace
per recording:

- The log is split into sessions where it pauses for longer than `--max-gap-s`, and each
  session into recordings of about `--cycles` program cycles, cut where a new cycle starts
  and no event is going on, so that a corpus can be cross-validated by recording.
- Each recording is resampled onto a uniform grid at `--rate-hz` (at least the 10 Hz a
  configuration allows) by holding the latest logged sample, as a detector polling the log
  would see it. A sample the logger dropped (a step of about 2 s) is thus held one second
  longer; a row whose robot values are missing holds the previous row's values.
- `truth` names each labelled event: `protective_stop` while the controller's protective
  stop flag is set, `grip_lost` while the lost-grip flag is. A missing flag counts as unset,
  unless both neighbouring rows have it set. A row holds one label: where one flag rises
  while the other's event goes on, the event going on keeps the rows (the script says how
  many events that hides).

Usage: python3 scripts/ur3_cobotops.py dataset_02052023.xlsx --out recordings/ur3
Bad input is refused with the line (or spreadsheet row) and column, and nothing is written.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass
from pathlib import Path

JOINTS = range(6)
# (trace channel, dataset column, unit): the dataset's currents are in amperes, its speeds
# in radians per second, already SI. Temperatures change over minutes and are left out.
CHANNELS = (
    [(f"current_j{j}", f"Current_J{j}", "A") for j in JOINTS]
    + [(f"speed_j{j}", f"Speed_J{j}", "rad/s") for j in JOINTS]
    + [("tool_current", "Tool_current", "A")]
)
# (trace label, dataset column); the first has precedence on a row where both rise at once.
EVENTS = (("protective_stop", "Robot_ProtectiveStop"), ("grip_lost", "grip_lost"))
TIMESTAMP = "Timestamp"
CYCLE = "cycle"
SOURCE = "UR3 CobotOps, UCI Machine Learning Repository, doi:10.24432/C5J891"
LICENCE = "CC BY 4.0 (M. Tyrovolas, K. Aliev, D. Antonelli, C. Stylios)"


class InputError(Exception):
    """Bad input, with a message naming where."""


@dataclass
class Row:
    where: str  # "line N" or "row N", for messages
    num: str  # the dataset's own row number, for the metadata
    t: float  # seconds since the epoch
    values: list[float | None]  # per CHANNELS; None where the cell is empty
    flags: list[bool | None]  # per EVENTS; None where the cell is empty
    cycle: str


def read_table(path: Path) -> tuple[list[str], list[tuple[str, list[str]]]]:
    """The header and the rows as text cells, each row with where it was read."""
    if path.suffix.lower() == ".xlsx":
        return read_xlsx(path)
    return read_csv(path)


def unquote(cell: str) -> str:
    """A cell's text without surrounding blanks and quotes (some of the sheet's cells are quoted)."""
    cell = cell.strip()
    if len(cell) >= 2 and cell[0] == cell[-1] == '"':
        cell = cell[1:-1].strip()
    return cell


def read_csv(path: Path) -> tuple[list[str], list[tuple[str, list[str]]]]:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read it as UTF-8 text: {e}") from e
    lines = text.splitlines()
    if not lines:
        raise InputError(f"{path}: empty: no header row")
    # A European spreadsheet export separates cells with `;` and writes decimal commas.
    sep = ";" if lines[0].count(";") > lines[0].count(",") else ","
    header = [h.strip() for h in lines[0].split(sep)]
    rows = []
    for n, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        cells = [unquote(c) for c in line.split(sep)]
        if sep == ";":
            cells = [c.replace(",", ".") for c in cells]
        rows.append((f"line {n}", cells))
    return header, rows


def read_xlsx(path: Path) -> tuple[list[str], list[tuple[str, list[str]]]]:
    ns = {"m": "http://schemas.openxmlformats.org/spreadsheetml/2006/main"}
    try:
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
            shared = []
            if "xl/sharedStrings.xml" in names:
                root = ET.fromstring(z.read("xl/sharedStrings.xml"))
                for si in root.findall("m:si", ns):
                    shared.append("".join(t.text or "" for t in si.iter(f"{{{ns['m']}}}t")))
            sheet = ET.fromstring(z.read("xl/worksheets/sheet1.xml"))
    except (OSError, zipfile.BadZipFile, KeyError, ET.ParseError) as e:
        raise InputError(f"{path}: not a readable spreadsheet (.xlsx): {e}") from e
    table = []
    for row in sheet.iter(f"{{{ns['m']}}}row"):
        cells: dict[int, str] = {}
        for c in row.findall("m:c", ns):
            ref = c.get("r", "")
            col = 0
            for ch in ref:
                if ch.isalpha():
                    col = col * 26 + ord(ch.upper()) - ord("A") + 1
            v = c.find("m:v", ns)
            text = "" if v is None or v.text is None else v.text
            kind = c.get("t")
            if kind == "s" and text:
                text = shared[int(text)]
            elif kind == "b":
                text = "True" if text == "1" else "False"
            elif kind == "inlineStr":
                text = "".join(t.text or "" for t in c.iter(f"{{{ns['m']}}}t"))
            cells[col - 1] = unquote(text)
        width = max(cells) + 1 if cells else 0
        table.append((f"row {row.get('r')}", [cells.get(i, "") for i in range(width)]))
    if not table:
        raise InputError(f"{path}: the first sheet is empty: no header row")
    header = table[0][1]
    return header, table[1:]


def parse_rows(path: Path) -> list[Row]:
    header, table = read_table(path)
    index = {h.strip().lower(): i for i, h in enumerate(header) if h.strip()}

    def col(name: str) -> int:
        i = index.get(name.lower())
        if i is None:
            raise InputError(f"{path}: the header has no column `{name}`")
        return i

    t_col, cycle_col = col(TIMESTAMP), col(CYCLE)
    value_cols = [col(src) for _, src, _ in CHANNELS]
    flag_cols = [col(src) for _, src in EVENTS]
    num_col = index.get("num")
    rows = []
    for where, cells in table:
        if not any(cells):
            continue
        cell = lambda i: cells[i] if i < len(cells) else ""  # noqa: E731
        stamp = cell(t_col)
        try:
            t = dt.datetime.fromisoformat(stamp.replace("Z", "+00:00")).timestamp()
        except ValueError:
            raise InputError(
                f"{path}: {where}, column `{TIMESTAMP}`: `{stamp}` is not an ISO 8601 time"
            ) from None
        values: list[float | None] = []
        for (_, src, _), i in zip(CHANNELS, value_cols):
            text = cell(i)
            if not text:
                values.append(None)
                continue
            try:
                x = float(text)
            except ValueError:
                raise InputError(f"{path}: {where}, column `{src}`: `{text}` is not a number") from None
            if not math.isfinite(x):
                raise InputError(f"{path}: {where}, column `{src}`: `{text}` is not finite")
            values.append(x)
        flags: list[bool | None] = []
        for (_, src), i in zip(EVENTS, flag_cols):
            text = cell(i).lower()
            if text in ("true", "1"):
                flags.append(True)
            elif text in ("false", "0"):
                flags.append(False)
            elif not text:
                flags.append(None)
            else:
                raise InputError(f"{path}: {where}, column `{src}`: `{cell(i)}` is not True or False")
        num = cell(num_col) if num_col is not None else where
        rows.append(Row(where, num, t, values, flags, cell(cycle_col)))
    if len(rows) < 2:
        raise InputError(f"{path}: {len(rows)} data rows: a recording needs at least two")
    for a, b in zip(rows, rows[1:]):
        if b.t <= a.t:
            raise InputError(
                f"{path}: {b.where}, column `{TIMESTAMP}`: time does not increase "
                f"(previous row at {dt.datetime.fromtimestamp(a.t, dt.timezone.utc).isoformat()})"
            )
    return rows


def fill(rows: list[Row], path: Path) -> int:
    """Holds the previous row's value where one is missing; returns the rows completed."""
    held = 0
    for i, r in enumerate(rows):
        missing = [k for k, v in enumerate(r.values) if v is None]
        if missing:
            if i == 0 or any(v is None for v in rows[i - 1].values):
                name = CHANNELS[missing[0]][1]
                raise InputError(f"{path}: {r.where}, column `{name}`: empty, and no earlier row to hold")
            for k in missing:
                r.values[k] = rows[i - 1].values[k]
            held += 1
        for e in range(len(EVENTS)):
            if r.flags[e] is None:
                before = i > 0 and rows[i - 1].flags[e] is True
                after = i + 1 < len(rows) and rows[i + 1].flags[e] is True
                r.flags[e] = before and after
    return held


def labels(rows: list[Row]) -> tuple[list[str], int]:
    """One label per row; and how many flag rises an event going on hid.

    An event starts on a row where its flag rises while no event is labelled; a flag that
    rises during another event is hidden for the whole of its run.
    """
    names = [name for name, _ in EVENTS]
    out, hidden, current = [], 0, ""
    previous = dict.fromkeys(names, False)
    for r in rows:
        on = {n: bool(f) for n, f in zip(names, r.flags)}
        rising = [n for n in names if on[n] and not previous[n]]
        if not (current and on[current]):
            current = rising[0] if rising else ""
        hidden += sum(1 for n in rising if n != current)
        out.append(current)
        previous = on
    return out, hidden


def split(rows: list[Row], truth: list[str], max_gap_s: float, cycles: int) -> list[range]:
    """Row ranges of the recordings: sessions cut at pauses, then about `cycles` cycles each."""
    pieces, start, seen = [], 0, 1
    for i in range(1, len(rows)):
        if rows[i].t - rows[i - 1].t > max_gap_s:
            pieces.append(range(start, i))
            start, seen = i, 1
            continue
        if rows[i].cycle != rows[i - 1].cycle:
            seen += 1
            quiet = not truth[i] and not truth[i - 1]
            if seen > cycles and quiet:
                pieces.append(range(start, i))
                start, seen = i, 1
    pieces.append(range(start, len(rows)))
    return [p for p in pieces if len(p) >= 2]


def resample(rows: list[Row], truth: list[str], piece: range, rate_hz: float):
    """Ticks of a uniform grid from the piece's first row until its last has arrived, each
    holding the latest row."""
    t0, t1 = rows[piece.start].t, rows[piece.stop - 1].t
    period = 1.0 / rate_hz
    n = int(math.ceil((t1 - t0) * rate_hz - 1e-9)) + 1
    ticks, j = [], piece.start
    for k in range(n):
        t = t0 + k * period
        while j + 1 < piece.stop and rows[j + 1].t <= t + 1e-9:
            j += 1
        ticks.append((k * period, rows[j].values, truth[j]))
    return ticks


def number(x: float) -> str:
    """The shortest text that reads back to the same value."""
    return repr(float(x))


def write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("input", type=Path, help="the dataset: dataset_02052023.xlsx, or a CSV export of it")
    p.add_argument("--out", type=Path, required=True, help="directory for the traces (new or empty)")
    p.add_argument("--rate-hz", type=float, default=10.0, help="trace rate (default 10, at least 10)")
    p.add_argument("--cycles", type=int, default=10, help="program cycles per recording (default 10)")
    p.add_argument("--max-gap-s", type=float, default=5.0, help="a longer pause starts a new session (s)")
    args = p.parse_args(argv)
    try:
        if not 10.0 <= args.rate_hz <= 50_000.0:
            raise InputError(f"--rate-hz {args.rate_hz}: a configuration runs at 10 to 50000 Hz")
        if args.cycles < 1:
            raise InputError(f"--cycles {args.cycles}: at least 1")
        if not args.max_gap_s > 0:
            raise InputError(f"--max-gap-s {args.max_gap_s}: must be positive")
        if args.out.exists() and (not args.out.is_dir() or any(args.out.iterdir())):
            raise InputError(f"{args.out}: exists and is not an empty directory (nothing written)")
        rows = parse_rows(args.input)
        held = fill(rows, args.input)
        truth, hidden = labels(rows)
        pieces = split(rows, truth, args.max_gap_s, args.cycles)
        files = []
        for n, piece in enumerate(pieces, start=1):
            ticks = resample(rows, truth, piece, args.rate_hz)
            first, last = rows[piece.start], rows[piece.stop - 1]
            start = dt.datetime.fromtimestamp(first.t, dt.timezone.utc).isoformat()
            meta = [
                ("source", SOURCE),
                ("licence", LICENCE),
                ("converted_by", "scripts/ur3_cobotops.py"),
                ("source_rows", f"{first.num}-{last.num}"),
                ("cycles", f"{first.cycle}-{last.cycle}"),
                ("start_utc", start),
                ("rate_hz", number(args.rate_hz)),
                ("source_rate_hz", "1 (held at rate_hz)"),
            ] + [(f"unit.{name}", unit) for name, _, unit in CHANNELS]
            lines = [f"# {k}: {v}" for k, v in meta]
            lines.append(",".join(["t"] + [name for name, _, _ in CHANNELS] + ["truth"]))
            for t, values, label in ticks:
                lines.append(",".join([number(round(t, 9))] + [number(v) for v in values] + [label]))
            files.append((f"ur3_cobotops_{n:02}.csv", "\n".join(lines) + "\n"))
        args.out.mkdir(parents=True, exist_ok=True)
        for name, text in files:
            write_atomic(args.out / name, text)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    except OSError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    events = {name: 0 for name, _ in EVENTS}
    for piece in pieces:
        for i in piece:
            if truth[i] and (i == piece.start or truth[i - 1] != truth[i]):
                events[truth[i]] += 1
    hours = sum(rows[p.stop - 1].t - rows[p.start].t for p in pieces) / 3600.0
    print(
        f"{len(files)} recordings, {hours:.2f} h, events: "
        + ", ".join(f"{k} {v}" for k, v in events.items())
        + f"; {held} rows with missing values held; {hidden} flag rises hidden by an event going on"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
