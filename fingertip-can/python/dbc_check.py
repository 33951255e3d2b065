#!/usr/bin/env python3
"""Cross-check of the fingertip CAN codec against the published DBC, through cantools.

Driven by fingertip/tests/can_dbc.rs. Reads one JSON request on stdin and writes one JSON
answer on stdout, so every frame of a test run goes through a single interpreter start.

Request:
    {"dbc": PATH,
     "decode": [{"id": INT, "data": HEX}, ...],        # frames our codec encoded
     "encode": [{"id": INT, "signals": {NAME: NUMBER}}, ...],   # values to encode
     "encode_invalid": [{"id": INT, "signals": {...}}, ...]}    # must be refused

Answer:
    {"messages": [...the database as cantools parsed it...],
     "decoded": [{"name": NAME, "signals": {...}, "crc_ok": BOOL|null} | {"error": TEXT}],
     "encoded": [{"data": HEX} | {"error": TEXT}],
     "encode_invalid": [{"data": HEX} | {"error": TEXT}]}

Every message of the protocol carries a `Crc`: it is computed and checked with cantools'
AUTOSAR E2E profile 5 functions, using the data id the protocol defines: the CAN id.
"""

import json
import sys

import cantools
from cantools.autosar.end_to_end import apply_profile5_crc, check_profile5_crc


def protected(msg):
    return any(s.name == "Crc" for s in msg.signals)


def tidy(value):
    """Physical values computed as raw * factor in binary floating point can land a hair
    outside a decimal range end (4095 * 0.002 = 8.190000000000001); 12 significant digits
    are far finer than any signal's resolution and read back exactly."""
    return float(f"{value:.12g}")


def describe(db):
    out = []
    for m in db.messages:
        sigs = []
        for s in m.signals:
            sigs.append({
                "name": s.name,
                "start": s.start,
                "length": s.length,
                "byte_order": s.byte_order,
                "signed": s.is_signed,
                "scale": s.scale,
                "offset": s.offset,
                "minimum": s.minimum,
                "maximum": s.maximum,
                "unit": s.unit or "",
                "is_multiplexer": s.is_multiplexer,
                "multiplexer_ids": s.multiplexer_ids,
                "choices": {str(int(k)): str(v) for k, v in (s.choices or {}).items()},
            })
        out.append({
            "id": m.frame_id,
            "name": m.name,
            "length": m.length,
            "extended": m.is_extended_frame,
            "fd": m.is_fd,
            "senders": list(m.senders),
            "cycle_time": m.cycle_time,
            "signals": sigs,
        })
    return out


def encode(db, item):
    msg = db.get_message_by_frame_id(item["id"])
    values = {k: tidy(v) for k, v in item["signals"].items()}
    data = msg.encode(values, scaling=True, strict=True)
    if protected(msg):
        data = apply_profile5_crc(bytes(data), item["id"])
    return bytes(data).hex()


def main():
    req = json.load(sys.stdin)
    db = cantools.database.load_file(req["dbc"], strict=True)
    answer = {"messages": describe(db), "decoded": [], "encoded": [], "encode_invalid": []}

    for item in req.get("decode", []):
        data = bytes.fromhex(item["data"])
        try:
            msg = db.get_message_by_frame_id(item["id"])
            values = msg.decode(data, decode_choices=False, scaling=True)
            res = {"name": msg.name, "signals": {k: float(v) for k, v in values.items()}}
            res["crc_ok"] = check_profile5_crc(data, item["id"]) if protected(msg) else None
        except Exception as e:  # reported to the Rust test, which fails on it
            res = {"error": f"{type(e).__name__}: {e}"}
        answer["decoded"].append(res)

    for key, out in (("encode", "encoded"), ("encode_invalid", "encode_invalid")):
        for item in req.get(key, []):
            try:
                answer[out].append({"data": encode(db, item)})
            except Exception as e:
                answer[out].append({"error": f"{type(e).__name__}: {e}"})

    json.dump(answer, sys.stdout)


if __name__ == "__main__":
    main()
