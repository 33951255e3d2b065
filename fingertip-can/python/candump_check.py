#!/usr/bin/env python3
"""Decodes a candump log with cantools, for fingertip/tests/can_tools.rs to compare with
its own decoder.

Usage: candump_check.py DBC LOG  -> JSON on stdout: one entry per line cantools' log
reader recognizes as a frame: {"line": N, "id": INT, "time": FLOAT|null,
"name": NAME, "signals": {...}} or {"line": N, "id": INT, "error": TEXT} when the DBC
cannot decode it (a bad length, say). Lines the reader does not recognize are left out.
"""

import json
import sys

import cantools
from cantools.logreader import Parser


def main():
    db = cantools.database.load_file(sys.argv[1], strict=True)
    out = []
    with open(sys.argv[2]) as f:
        for n, line in enumerate(f, start=1):
            frame = Parser().parse(line)
            if frame is None:
                continue
            item = {"line": n, "id": frame.frame_id}
            ts = frame.timestamp
            item["time"] = ts.timestamp() if hasattr(ts, "timestamp") else (
                ts.total_seconds() if hasattr(ts, "total_seconds") else None)
            try:
                msg = db.get_message_by_frame_id(frame.frame_id)
                item["name"] = msg.name
                values = msg.decode(frame.data, decode_choices=False, scaling=True)
                item["signals"] = {k: float(v) for k, v in values.items()}
            except Exception as e:  # reported, compared with our own verdict
                item["error"] = f"{type(e).__name__}: {e}"
            out.append(item)
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
