"""VMC frames received: what `imubake live` (or any VMC performer) sends, read without blocking.

`Receiver(port)` binds a non-blocking UDP socket on 127.0.0.1 (or `host`); `drain()` reads every
datagram waiting, decodes it (`osc`), and returns the newest complete frame — a bundle with bone
poses — dropping older ones (a viewer shows the latest pose; a recording keys what it shows).
Bad packets (not OSC, wrong argument types, a non-finite number) are counted and ignored, never
raised. No bpy here: Blender's timer calls `drain()` and poses the character with the frame.

A frame's values are as VMC sends them, in Unity's left-handed axes (X right, Y up, Z forward):
`bones[name] = (position (x, y, z) metres, rotation (x, y, z, w))`, local to the parent;
`root` the same for the model's root; `t` the sender's time (seconds), when it sent one.
"""

import math
import socket

from . import osc

CALIBRATE = "/VMC/Ext/Set/Calib/Exec"


class Frame:
    def __init__(self):
        self.bones = {}
        self.root = None
        self.t = None

    def __repr__(self):
        return "Frame(t=%r, %d bones)" % (self.t, len(self.bones))


def _pose(args):
    """(name, position, rotation) from Root/Pos or Bone/Pos arguments, or None if malformed."""
    if len(args) < 8 or not isinstance(args[0], str):
        return None
    nums = args[1:8]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in nums):
        return None
    return args[0], tuple(float(v) for v in nums[:3]), tuple(float(v) for v in nums[3:7])


class Receiver:
    def __init__(self, port=39539, host="127.0.0.1"):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind((host, port))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.packets = 0
        self.bad = 0
        self.frames = 0
        self.dropped = 0
        self.ok = None  # the last /VMC/Ext/OK arguments

    def close(self):
        self.sock.close()

    def drain(self, limit=10000):
        """Reads what is waiting; the newest complete frame, or None when none came."""
        newest = None
        for _ in range(limit):
            try:
                data, _ = self.sock.recvfrom(65536)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self.bad += 1
                break
            self.packets += 1
            frame = self._frame(data)
            if frame is None:
                continue
            if newest is not None:
                self.dropped += 1
            newest = frame
            self.frames += 1
        return newest

    def _frame(self, data):
        try:
            messages = osc.decode(data)
        except osc.OscError:
            self.bad += 1
            return None
        frame, bad = Frame(), False
        for address, args in messages:
            if address == "/VMC/Ext/Bone/Pos":
                pose = _pose(args)
                if pose is None:
                    bad = True
                    continue
                frame.bones[pose[0]] = pose[1:]
            elif address == "/VMC/Ext/Root/Pos":
                pose = _pose(args)
                if pose is None:
                    bad = True
                    continue
                frame.root = pose[1:]
            elif address == "/VMC/Ext/T":
                if args and isinstance(args[0], (int, float)) and math.isfinite(args[0]):
                    frame.t = float(args[0])
                else:
                    bad = True
            elif address == "/VMC/Ext/OK":
                self.ok = list(args)
        if bad:
            self.bad += 1
        return frame if frame.bones else None


def calibration_request(mode=0):
    """The datagram asking a performer (`imubake live --listen`) to calibrate again."""
    import struct

    def pad(b):
        return b + b"\0" * (4 - len(b) % 4)

    return pad(CALIBRATE.encode()) + pad(b",i") + struct.pack(">i", mode)
