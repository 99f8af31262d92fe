"""Receiving VMC in Blender (issue 19, first part): the add-on's own OSC decoder (`osc.py`) and the
non-blocking receiver (`vmc.py`) against packets encoded by PyPI's python-osc, malformed packets,
and a real `imubake live` session streaming into the receiver."""

import math
import os
import socket
import struct
import subprocess
import time
import unittest

import harness
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder


def message(address, *args):
    b = OscMessageBuilder(address=address)
    for a in args:
        b.add_arg(a)
    return b.build()


def frame_bundle(t, bones, root=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)):
    b = OscBundleBuilder(IMMEDIATELY)
    b.add_content(message("/VMC/Ext/Root/Pos", "root", *root))
    for name, values in bones.items():
        b.add_content(message("/VMC/Ext/Bone/Pos", name, *values))
    b.add_content(message("/VMC/Ext/T", t))
    return b.build().dgram


def f32(x):
    return struct.unpack(">f", struct.pack(">f", x))[0]


class Decoder(unittest.TestCase):
    def setUp(self):
        self.osc = harness.submodule("osc")

    def test_python_osc_packets_decode(self):
        bones = {"LeftUpperArm": (0.1, 0.2, 0.3, 0.0, 0.38268343, 0.0, 0.92387953)}
        decoded = self.osc.decode(frame_bundle(1.25, bones))
        self.assertEqual([a for a, _ in decoded], ["/VMC/Ext/Root/Pos", "/VMC/Ext/Bone/Pos", "/VMC/Ext/T"])
        name, *values = decoded[1][1]
        self.assertEqual(name, "LeftUpperArm")
        self.assertEqual(values, [f32(v) for v in bones["LeftUpperArm"]])
        self.assertEqual(decoded[2][1], [1.25])
        # Other argument types python-osc writes: int, string, blob, booleans, None, double.
        m = message("/x", 7, "abc", b"\x01\x02\x03", True, False, None)
        self.assertEqual(self.osc.decode(m.dgram), [("/x", [7, "abc", b"\x01\x02\x03", True, False, None])])
        b = OscMessageBuilder(address="/d")
        b.add_arg(2.5, arg_type="d")
        self.assertEqual(self.osc.decode(b.build().dgram), [("/d", [2.5])])

    def test_malformed_packets_are_errors_not_crashes(self):
        good = frame_bundle(0.5, {"Hips": (0, 1, 0, 0, 0, 0, 1)})
        for bad in (b"", b"\x00\x01", b"#bundle\x00", good[:-5], good[:20] + b"\xff\xff\xff\x7f" + good[24:],
                    b"/x\x00\x00,q\x00\x00", b"x\x00\x00\x00", b"/x\x00\x00,i\x00\x00\x00\x01"):
            with self.assertRaises(self.osc.OscError, msg=repr(bad)):
                self.osc.decode(bad)


class Receiving(unittest.TestCase):
    def setUp(self):
        self.vmc = harness.submodule("vmc")
        self.rx = self.vmc.Receiver(port=0)
        self.tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.to = ("127.0.0.1", self.rx.port)

    def tearDown(self):
        self.rx.close()
        self.tx.close()

    def send(self, data):
        self.tx.sendto(data, self.to)

    def test_the_newest_frame_is_kept_and_bad_packets_counted(self):
        bone = (0.0, 0.1, 0.0, 0.0, 0.0, 0.0, 1.0)
        for t in (0.1, 0.2, 0.3):
            self.send(frame_bundle(t, {"Hips": bone, "LeftUpperArm": bone}))
        good = frame_bundle(0.4, {"Hips": bone})
        self.send(b"\x00\x01")  # not OSC
        self.send(good[:-5])  # truncated
        self.send(frame_bundle(0.5, {"Hips": (0, 0, 0, float("nan"), 0, 0, 1)}))  # NaN
        self.send(message("/VMC/Ext/Bone/Pos", "Hips", "x", 0.0, 0.0, 0.0, 0.0, 0.0, 1.0).dgram)  # a string
        time.sleep(0.2)
        frame = self.rx.drain()
        self.assertIsNotNone(frame)
        self.assertAlmostEqual(frame.t, f32(0.3), places=7)
        self.assertEqual(sorted(frame.bones), ["Hips", "LeftUpperArm"])
        self.assertEqual(self.rx.packets, 7)
        self.assertEqual(self.rx.frames, 3)
        self.assertEqual(self.rx.dropped, 2)
        self.assertEqual(self.rx.bad, 4)
        self.assertIsNone(self.rx.drain(), "nothing new")

    def test_the_calibration_request_is_what_python_osc_reads(self):
        m = OscMessage(self.vmc.calibration_request())
        self.assertEqual((m.address, m.params), ("/VMC/Ext/Set/Calib/Exec", [0]))

    def test_imubake_live_streams_into_the_receiver(self):
        repo = os.environ["IMUBAKE_REPO"]
        listen = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        listen.bind(("127.0.0.1", 0))
        listen_port = listen.getsockname()[1]
        listen.close()
        live = subprocess.Popen(
            [os.environ["IMUBAKE_BIN"], "live",
             "--source", "file:%s@4" % os.path.join(repo, "samples", "walk.csv"),
             "--mapping", os.path.join(repo, "mappings", "paper000_16imu_mixamo.json"),
             "--vmc", "127.0.0.1:%d" % self.rx.port, "--listen", "127.0.0.1:%d" % listen_port],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        times, names, asked = [], set(), False
        while True:
            frame = self.rx.drain()
            if frame is not None:
                times.append(frame.t)
                names.update(frame.bones)
                if not asked and len(times) > 30:
                    # Recalibrate, as the panel's button will: the session says it is calibrating.
                    self.tx.sendto(self.vmc.calibration_request(), ("127.0.0.1", listen_port))
                    asked = True
            if live.poll() is not None:
                break
            time.sleep(0.02)  # a 50 Hz timer
        err = live.stderr.read().decode()
        self.assertEqual(live.returncode, 0, err)
        self.assertIn("calibrating: hold the pose", err)
        self.assertEqual(self.rx.bad, 0)
        self.assertGreater(len(times), 100)
        self.assertTrue(all(b > a for a, b in zip(times, times[1:])), "newer frames only")
        for t in times:
            self.assertLess(abs(t * 60 - round(t * 60)), 1e-3, "on the 60 fps grid")
        self.assertTrue({"Hips", "LeftUpperArm", "RightLowerLeg", "UpperChest"} <= names, names)
        self.assertEqual(self.rx.ok[:1], [1])


if __name__ == "__main__":
    unittest.main()
