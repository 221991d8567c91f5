#!/usr/bin/env python3
"""A fake grandMA3 OSC input for the MA3 tests: an OSC data line with "Receive Command" on,
as MA3's manual describes it: each UDP message /<prefix>/cmd <string> is one command line,
run in the programmer of the user the line is bound to; MA3 sends nothing back. Bundles
are not taken (MA3 does not read them): each one is recorded as an error.

The commands it runs (MA3 syntax, keywords as MA3 writes them):
  Fixture <list>                              selects (1 Thru 4 + 7)
  Fixture <list> Attribute "<name>" At <v>    sets an attribute in percent (At 5 is 5 %)
  Fixture <list> At Preset <pool>.<n>         puts a preset in the programmer (kept as
                                              "Preset": "<pool>.<n>")
  Store Preset <pool>.<n> /Overwrite          stores the selection's programmer values
  Store Sequence <s> Cue <c> /Overwrite       likewise, as a cue
  Label Preset <pool>.<n> "<text>"            labels a stored preset
  Label Sequence <s> Cue <c> "<text>"         labels a stored cue
  Set Sequence <s> Cue <c> Property "CueInFade" <t>   the cue's fade, seconds
  Off Fixture <list>                          takes the fixtures out of the programmer
Anything else is recorded as an error.

Usage: fake_ma3.py --prefix gma3 --state FILE          listens on UDP 127.0.0.1 (prints
                                                       the port), serves until killed
       fake_ma3.py --replay FILE --state FILE          runs FILE's commands, one a line
After every command the state (commands, errors, programmer, presets, cues) goes to the
state file as JSON (a temporary file renamed over it).
"""

import argparse
import json
import os
import re
import shlex
import socket
import sys

from pythonosc.osc_message import OscMessage

from osc_stream import selection


class Desk:
    def __init__(self, state):
        self.state_path = state
        self.commands, self.errors = [], []
        self.programmer, self.selection = {}, []
        self.presets, self.cues = {}, {}

    def run(self, line):
        self.commands.append(line)
        try:
            w = shlex.split(line)
        except ValueError:
            w = []
        ok = self.command(w)
        if not ok:
            self.errors.append(line)
        self.save()

    def stored(self):
        return {str(f): dict(self.programmer.get(f, {})) for f in self.selection
                if self.programmer.get(f)}

    def command(self, w):
        if len(w) >= 2 and w[0] == "Fixture":
            if "Attribute" in w:
                i = w.index("Attribute")
                if len(w) != i + 4 or w[i + 2] != "At":
                    return False
                for f in selection(w[1:i]):
                    self.programmer.setdefault(f, {})[w[i + 1]] = float(w[i + 3])
                return True
            if "At" in w:
                i = w.index("At")
                if w[i + 1:i + 2] != ["Preset"] or len(w) != i + 3:
                    return False
                if not re.fullmatch(r"\d+\.\d+", w[i + 2]):
                    return False
                for f in selection(w[1:i]):
                    self.programmer.setdefault(f, {})["Preset"] = w[i + 2]
                return True
            self.selection = selection(w[1:])
            return True
        if len(w) >= 3 and w[0] == "Off" and w[1] == "Fixture":
            for f in selection(w[2:]):
                self.programmer.pop(f, None)
            return True
        if w[:2] == ["Store", "Preset"] and len(w) == 4 and w[3] == "/Overwrite":
            if not re.fullmatch(r"\d+\.\d+", w[2]):
                return False
            self.presets[w[2]] = {"label": "", "values": self.stored()}
            return True
        if w[:2] == ["Store", "Sequence"] and len(w) == 6 and w[3] == "Cue" and w[5] == "/Overwrite":
            self.cues["%s/%s" % (w[2], w[4])] = {"label": "", "fade": None, "values": self.stored()}
            return True
        if w[:2] == ["Label", "Preset"] and len(w) == 4:
            if w[2] not in self.presets:
                return False
            self.presets[w[2]]["label"] = w[3]
            return True
        if w[:2] == ["Label", "Sequence"] and len(w) == 6 and w[3] == "Cue":
            key = "%s/%s" % (w[2], w[4])
            if key not in self.cues:
                return False
            self.cues[key]["label"] = w[5]
            return True
        if (w[:2] == ["Set", "Sequence"] and len(w) == 8 and w[3] == "Cue"
                and w[5] == "Property" and w[6] == "CueInFade"):
            key = "%s/%s" % (w[2], w[4])
            if key not in self.cues:
                return False
            self.cues[key]["fade"] = float(w[7])
            return True
        return False

    def save(self):
        tmp = self.state_path + ".tmp"
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump({"commands": self.commands, "errors": self.errors,
                       "programmer": {str(k): v for k, v in self.programmer.items()},
                       "presets": self.presets, "cues": self.cues}, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.state_path)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--prefix", default="gma3")
    ap.add_argument("--replay")
    ap.add_argument("--state", required=True)
    a = ap.parse_args()
    desk = Desk(a.state)
    desk.save()
    if a.replay:
        with open(a.replay, encoding="utf-8") as f:
            for line in f:
                if line.strip():
                    desk.run(line.rstrip("\n"))
        return 0
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    print(sock.getsockname()[1], flush=True)
    want = "/%s/cmd" % a.prefix
    while True:
        data, _ = sock.recvfrom(65536)
        if data.startswith(b"#bundle"):
            desk.errors.append("a bundle")
            desk.save()
            continue
        msg = OscMessage(data)
        if msg.address != want or len(msg.params) != 1 or not isinstance(msg.params[0], str):
            desk.errors.append("%s %r" % (msg.address, msg.params))
            desk.save()
            continue
        desk.run(msg.params[0])


if __name__ == "__main__":
    sys.exit(main())
