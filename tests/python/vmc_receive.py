#!/usr/bin/env python3
"""Receives a VMC stream (OSC over UDP) with python-osc's own decoder, independently of imubake.

usage: vmc_receive.py OUT.json [--idle S] [--max S]
Binds 127.0.0.1 on a free port and prints the port on stdout at once (one line). Receives until
nothing has come for --idle seconds (default 2) after the first datagram, or --max seconds
(default 120) in all, then writes OUT.json:
{"bundles": [{"arrival_s": s, "addresses": [...], "root": [7 floats] | null,
              "bones": {name: [px, py, pz, qx, qy, qz, qw]}, "t": float | null}],
 "messages": [[address, args...] for each datagram that is not a bundle]}
"""
import json
import socket
import sys
import time

from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_message import OscMessage


def walk(bundle):
    for item in bundle:
        if isinstance(item, OscBundle):
            yield from walk(item)
        else:
            yield item


def main():
    out = sys.argv[1]
    idle = float(sys.argv[sys.argv.index("--idle") + 1]) if "--idle" in sys.argv else 2.0
    longest = float(sys.argv[sys.argv.index("--max") + 1]) if "--max" in sys.argv else 120.0
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 * 1024 * 1024)
    print(sock.getsockname()[1], flush=True)
    start = time.monotonic()
    last = None
    bundles, messages = [], []
    sock.settimeout(0.1)
    while time.monotonic() - start < longest:
        if last is not None and time.monotonic() - last > idle:
            break
        try:
            data, _ = sock.recvfrom(65536)
        except socket.timeout:
            continue
        last = time.monotonic()
        if OscBundle.dgram_is_bundle(data):
            b = {"arrival_s": last - start, "addresses": [], "root": None, "bones": {}, "t": None}
            for m in walk(OscBundle(data)):
                b["addresses"].append(m.address)
                if m.address == "/VMC/Ext/Root/Pos":
                    b["root"] = list(m.params[1:])
                elif m.address == "/VMC/Ext/Bone/Pos":
                    b["bones"][m.params[0]] = list(m.params[1:])
                elif m.address == "/VMC/Ext/T":
                    b["t"] = m.params[0]
            bundles.append(b)
        else:
            m = OscMessage(data)
            messages.append([m.address] + list(m.params))
    with open(out, "w") as f:
        json.dump({"bundles": bundles, "messages": messages}, f)


if __name__ == "__main__":
    main()
