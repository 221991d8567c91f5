#!/usr/bin/env python3
"""A fake ETC Eos console for the record tests: a command line per OSC user, cue lists,
presets and cues, answering over OSC as Eos documents it (Eos Family Operations Manual,
"Show Control > OSC"; ETCLabs' EosSyncLib for the read-back formats):

  /eos/user/<n>/newcmd <text>  clears user n's command line and types <text>; a text that
                               ends in "Enter" runs. The user's command line is echoed on
                               /eos/out/user/<n>/cmd ("LIVE: <command> #", or
                               "LIVE: Error: <why>" when it was refused).
  /eos/get/preset/<n>          -> /eos/out/get/preset/<n>/list/0/5
                                  (index, UID, label, absolute, locked); nothing if absent
  /eos/get/cue/<list>/<cue>    -> /eos/out/get/cue/<list>/<cue>/0/list/0/5
                                  (index, UID, label, up time in ms, down time in ms);
                                  nothing if absent

Commands run (channel selections with Thru and +):
  Chan <sel> At <level>                      Eos reads a one-digit level as tens: At 5 is
                                             50 %, At 05 is 5 %; Full is 100
  Chan <sel> <Param> <level> [<Param> <level> ...]   Red, Green, ... (same reading)
  Chan <sel> Pan <deg> Tilt <deg>            degrees, read as levels are (one digit: tens)
  Chan <sel> Focus_Palette <n>               refused with "Focus Palette Does Not Exist"
                                             for a palette it does not have (--fp)
  Chan <sel> Record Preset <n>               stores the selected channels' levels
  Chan <sel> Record Cue <list>/<cue>         refused with "Cue List Does Not Exist" for a
                                             list the console does not have (--lists)
  Cue <list>/<cue> Time <s>                  the cue's up and down time
  Cue <list>/<cue> Label <text>              the cue's label
Anything else is refused ("Error: Syntax Error").

Messages are parsed and built with python-osc; the TCP framing (OSC 1.0 length prefix,
or SLIP with --protocol tcp-slip) is osc_stream.py's. Over UDP (--protocol udp) the answers
go to 127.0.0.1:--tx, as Eos sends to its OSC TX address, not back to the sender.

Usage: fake_eos_console.py --protocol tcp|tcp-slip|udp [--tx PORT] [--port PORT]
                           [--lists 1,2] [--fp N=LABEL=CHANNELS ...] [--silent]
                           --state FILE
Prints the port it listens on (127.0.0.1; --port, or any), then serves until killed. After every
command it writes the state (each user's command lines, presets, cues) to FILE as JSON
(a temporary file renamed over it). --silent: takes everything, answers nothing.
"""

import argparse
import json
import os
import re
import socket
import sys
import threading

from pythonosc.osc_message import OscMessage

from osc_stream import build, focus_palettes, framed, frames, palette_replies, selection


def level(text):
    """A level typed on Eos's command line, in percent (or degrees for pan and tilt)."""
    if text.lower() in ("full", "fl"):
        return 100.0
    if re.fullmatch(r"-?[0-9]", text):
        return float(text) * 10.0
    return float(text)


def cue_key(text):
    lst, num = text.split("/")
    return "%d/%s" % (int(lst), ("%g" % float(num)))


class Console:
    def __init__(self, lists, palettes, state):
        self.lists = lists
        self.palettes = palettes
        self.state_path = state
        self.lines = {}
        self.live = {}
        self.presets = {}
        self.cues = {}
        self.lock = threading.Lock()

    def run(self, text):
        """Runs one command (without its Enter); returns an error text or None."""
        w = text.split()
        if len(w) >= 3 and w[0] == "Chan":
            rest = w[1:]
            for i, word in enumerate(rest):
                if word not in ("Thru", "+") and not word.isdigit():
                    break
            else:
                return "Syntax Error"
            sel, tail = selection(rest[:i]), rest[i:]
            if tail[0] == "Record" and len(tail) == 3 and tail[1] == "Preset":
                self.presets[tail[2]] = {
                    "label": "", "levels": {str(c): dict(self.live.get(c, {})) for c in sel}}
                return None
            if tail[0] == "Record" and len(tail) == 3 and tail[1] == "Cue":
                key = cue_key(tail[2])
                if int(key.split("/")[0]) not in self.lists:
                    return "Cue List Does Not Exist"
                self.cues[key] = {"label": "", "time": None,
                                  "levels": {str(c): dict(self.live.get(c, {})) for c in sel}}
                return None
            if tail[0] == "Focus_Palette" and len(tail) == 2:
                if tail[1] not in [p[0] for p in self.palettes]:
                    return "Focus Palette Does Not Exist"
                for c in sel:
                    self.live.setdefault(c, {})["Focus_Palette"] = float(tail[1])
                return None
            if len(tail) % 2:
                return "Syntax Error"
            for p in range(0, len(tail), 2):
                try:
                    v = level(tail[p + 1])
                except ValueError:
                    return "Syntax Error"
                for c in sel:
                    self.live.setdefault(c, {})[tail[p]] = v
            return None
        if len(w) >= 4 and w[0] == "Cue":
            key = cue_key(w[1])
            if key not in self.cues:
                return "Cue Does Not Exist"
            if w[2] == "Time" and len(w) == 4:
                self.cues[key]["time"] = float(w[3])
                return None
            if w[2] == "Label":
                self.cues[key]["label"] = " ".join(w[3:])
                return None
        return "Syntax Error"

    def handle(self, msg, answer):
        m = re.fullmatch(r"/eos/user/(\d+)/newcmd", msg.address)
        if m and msg.params and isinstance(msg.params[0], str):
            user, text = m.group(1), msg.params[0]
            self.lines.setdefault(user, []).append(text)
            if text.endswith(" Enter"):
                why = self.run(text[: -len(" Enter")])
                echo = "LIVE: Error: %s" % why if why else "LIVE: %s #" % text[: -len(" Enter")]
            else:
                echo = "LIVE: %s" % text
            answer("/eos/out/user/%s/cmd" % user, [echo])
        elif msg.address.startswith("/eos/get/preset/"):
            n = msg.address.rsplit("/", 1)[1]
            if n in self.presets:
                answer("/eos/out/get/preset/%s/list/0/5" % n,
                       [0, "uid-p%s" % n, self.presets[n]["label"], 0, 0])
        elif msg.address == "/eos/get/fp/count":
            answer("/eos/out/get/fp/count", [len(self.palettes)])
        elif msg.address.startswith("/eos/get/fp/index/"):
            i = int(msg.address.rsplit("/", 1)[1])
            if 0 <= i < len(self.palettes):
                for address, args in palette_replies(i, self.palettes[i]):
                    answer(address, args)
        elif msg.address.startswith("/eos/get/cue/"):
            key = cue_key("/".join(msg.address.split("/")[4:6]))
            if key in self.cues:
                c = self.cues[key]
                ms = int(round((c["time"] or 0) * 1000))
                answer("/eos/out/get/cue/%s/0/list/0/5" % key,
                       [0, "uid-c%s" % key, c["label"], ms, ms])
        self.save()

    def save(self):
        tmp = self.state_path + ".tmp"
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump({"lines": self.lines, "presets": self.presets, "cues": self.cues}, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.state_path)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--protocol", choices=["tcp", "tcp-slip", "udp"], required=True)
    ap.add_argument("--tx", type=int)
    ap.add_argument("--port", type=int, default=0)
    ap.add_argument("--lists", default="1")
    ap.add_argument("--fp", action="append", default=[])
    ap.add_argument("--silent", action="store_true")
    ap.add_argument("--state", required=True)
    a = ap.parse_args()
    console = Console({int(x) for x in a.lists.split(",") if x}, focus_palettes(a.fp), a.state)
    console.save()

    if a.protocol == "udp":
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", a.port))
        print(sock.getsockname()[1], flush=True)

        def answer(address, args):
            if not a.silent:
                sock.sendto(build(address, args), ("127.0.0.1", a.tx))

        while True:
            data, _ = sock.recvfrom(65536)
            with console.lock:
                console.handle(OscMessage(data), answer)

    slip = a.protocol == "tcp-slip"
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.bind(("127.0.0.1", a.port))
    srv.listen(4)
    print(srv.getsockname()[1], flush=True)
    while True:
        conn, _ = srv.accept()

        def answer(address, args, conn=conn):
            if not a.silent:
                conn.sendall(framed(build(address, args), slip))

        try:
            for frame in frames(conn, slip):
                with console.lock:
                    console.handle(OscMessage(frame), answer)
        except OSError:
            pass
        conn.close()


if __name__ == "__main__":
    sys.exit(main())
