#!/usr/bin/env python3
"""A fake ETC Eos console for the import tests: serves a patch over OSC TCP on loopback.

It answers as ETC's "Eos Integration via OSC" (Eos 2.6; in ETCLabs' EosSyncLib) documents:
  /eos/get/patch/count         -> /eos/out/get/patch/count <n>
  /eos/get/patch/index/<i>     -> /eos/out/get/patch/<ch>/<part>/list/<offset>/<total>
                                  index, UID, label, manufacturer, model, address,
                                  intensity address, level, gel, text 1-10, part count,
                                  end address (21 arguments)
  /eos/get/group/count         -> /eos/out/get/group/count <n>
  /eos/get/group/index/<i>     -> /eos/out/get/group/<g>/list/0/3 (index, UID, label) and
                                  /eos/out/get/group/<g>/channels/list/<offset>/<total>
                                  (index, UID, channel ranges as strings)
  /eos/get/fp/count            -> /eos/out/get/fp/count <n>
  /eos/get/fp/index/<i>        -> the palette's list, channel list and by-type list
                                  (osc_stream.palette_replies)
Every patch reply and every group channel list is split over two messages by offset (the
OSC list convention), with unsolicited /eos/out/ping and /eos/out/active/chan messages in
between, as a console with OSC TX on sends them all the time.

The patch comes from an Eos CSV export read with Python's own csv module (the rows of one
channel are its parts, in order; U/A and U/A<E addresses become absolute ones), so the
console serves the same patch the CSV holds. Messages are built with python-osc; the TCP
framing (OSC 1.0 length prefix, or SLIP with --slip) is osc_stream.py's.

Usage: fake_eos.py --csv FILE [--group LABEL=1-2,11 ...] [--slip] [--hang-after N]
                   [--groups-reported N] [--delay S] [--fp N=LABEL=CHANNELS ...]
                   [--fp-silent]
Prints the port it listens on (127.0.0.1), then serves one connection.
--hang-after N: answers N patch indexes, sends the first half of the next reply, then
stays silent (the connection open) until the client goes away.
--groups-reported N: answers the group count with N whatever groups it has.
--delay S: waits S seconds before each patch reply (a console that answers, slowly).
--fp-silent: answers nothing about focus palettes (the connection stays open).
"""

import argparse
import csv
import socket
import sys
import time

from pythonosc.osc_message import OscMessage

from osc_stream import build, focus_palettes, framed, frames, palette_replies


def absolute(text):
    """Absolute Eos address of U/A (or a plain number); 0 when empty."""
    text = text.strip()
    if not text:
        return 0
    if "/" in text:
        u, a = text.split("/")
        return (int(u) - 1) * 512 + int(a)
    return int(text)


def read_csv(path):
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    start = next(i for i, r in enumerate(rows) if r and r[0] == "START_CHANNELS")
    header = rows[start + 1]
    col = {name: i for i, name in enumerate(header)}
    parts = []
    seen = {}
    for r in rows[start + 2:]:
        if r and r[0] == "END_CHANNELS":
            break
        ch = int(r[col["CHANNEL"]])
        seen[ch] = seen.get(ch, 0) + 1
        addr = r[col["ADDRESS"]].strip()
        first, end = (addr.split("<") + [None])[:2]
        start_abs = absolute(first)
        if end is None:
            end_abs = start_abs
        elif "/" in end:
            end_abs = absolute(end)
        else:
            end_abs = (start_abs - 1) // 512 * 512 + int(end)
        parts.append({
            "channel": ch, "part": seen[ch], "label": r[col["LABEL"]],
            "manufacturer": r[col["MANUFACTURER"]], "model": r[col["FIXTURE_TYPE"]],
            "address": start_abs, "end": end_abs if start_abs else 0,
        })
    count = {}
    for p in parts:
        count[p["channel"]] = count.get(p["channel"], 0) + 1
    for p in parts:
        p["parts"] = count[p["channel"]]
    return parts


def uid(n):
    return "%08X-0000-0000-0000-%012X" % (n, n)


class Link:
    def __init__(self, conn, slip):
        self.conn = conn
        self.slip = slip

    def send(self, address, args):
        self.conn.sendall(framed(build(address, args), self.slip))

    def noise(self):
        self.send("/eos/out/ping", [])
        self.send("/eos/out/active/chan", ["11 LED PAR 64 RGBW @ 0 [0]"])

    def split(self, address, args, at):
        """Sends `args` as two messages of one OSC list, split at position `at`."""
        total = len(args)
        self.send("%s/list/0/%d" % (address, total), args[:at])
        self.noise()
        self.send("%s/list/%d/%d" % (address, at, total), args[at:])


def requests(conn, slip):
    """OSC addresses the client sends, one at a time."""
    for frame in frames(conn, slip):
        yield OscMessage(frame).address


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--csv", required=True)
    ap.add_argument("--group", action="append", default=[])
    ap.add_argument("--slip", action="store_true")
    ap.add_argument("--hang-after", type=int)
    ap.add_argument("--groups-reported", type=int)
    ap.add_argument("--delay", type=float, default=0.0)
    ap.add_argument("--fp", action="append", default=[])
    ap.add_argument("--fp-silent", action="store_true")
    a = ap.parse_args()
    parts = read_csv(a.csv)
    palettes = focus_palettes(a.fp)
    groups = []
    for g in a.group:
        label, chans = g.split("=", 1)
        groups.append((label, [c for c in chans.split(",") if c]))

    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    print(srv.getsockname()[1], flush=True)
    conn, _ = srv.accept()
    link = Link(conn, a.slip)
    link.noise()
    answered = 0
    hung = False
    for address in requests(conn, a.slip):
        if hung:
            continue
        if address == "/eos/get/patch/count":
            link.send("/eos/out/get/patch/count", [len(parts)])
        elif address.startswith("/eos/get/patch/index/"):
            i = int(address.rsplit("/", 1)[1])
            p = parts[i]
            args = [i, uid(i + 1), p["label"], p["manufacturer"], p["model"], p["address"],
                    p["address"], 0, ""] + [""] * 10 + [p["parts"], p["end"]]
            base = "/eos/out/get/patch/%d/%d" % (p["channel"], p["part"])
            time.sleep(a.delay)
            if a.hang_after is not None and answered == a.hang_after:
                link.send("%s/list/0/%d" % (base, len(args)), args[:9])
                hung = True
                continue
            link.split(base, args, 9)
            answered += 1
        elif address == "/eos/get/group/count":
            reported = len(groups) if a.groups_reported is None else a.groups_reported
            link.send("/eos/out/get/group/count", [reported])
        elif address.startswith("/eos/get/group/index/"):
            i = int(address.rsplit("/", 1)[1])
            label, chans = groups[i]
            n = i + 1
            link.send("/eos/out/get/group/%d/list/0/3" % n, [i, uid(1000 + n), label])
            link.split("/eos/out/get/group/%d/channels" % n, [i, uid(1000 + n)] + chans, 2)
        elif address == "/eos/get/fp/count" and not a.fp_silent:
            link.send("/eos/out/get/fp/count", [len(palettes)])
        elif address.startswith("/eos/get/fp/index/") and not a.fp_silent:
            i = int(address.rsplit("/", 1)[1])
            for reply, args in palette_replies(i, palettes[i]):
                link.send(reply, args)
                link.noise()
    conn.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
