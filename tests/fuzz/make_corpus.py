#!/usr/bin/env python3
"""Writes the fuzz targets' seed corpora, tests/fuzz/corpus/NAME/, from small excerpts of the
real data (../shared/data: CARMEN laser logs, g2o graphs, KITTI text files), the project's own
configuration files, and messages and byte streams made the way the emulators and drivers
make them (SCIP 2.0 responses as the URG emulator sends them, Kobuki feedback packets, LCM
messages of every type, encoded by lcm-gen's Python output of lcmtypes/*/*.lcm).

    tests/fuzz/make_corpus.py [--data ../shared/data]

Deterministic (same files every run); a few hundred KB in all. Run it again after changing a
message type, a file format or a target's input layout (tests/fuzz/fuzz_messages.hpp).
"""
import argparse
import gzip
import importlib
import math
import os
import random
import shutil
import struct
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT = os.path.join(ROOT, "tests", "fuzz", "corpus")


def write(name, file, data):
    d = os.path.join(OUT, name)
    os.makedirs(d, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    with open(os.path.join(d, file), "wb") as f:
        f.write(data)


def head_lines(path, n, pred=None):
    opener = gzip.open if path.endswith(".gz") else open
    out = []
    with opener(path, "rt", errors="replace") as f:
        for line in f:
            if pred is None or pred(line):
                out.append(line)
                if len(out) >= n:
                    break
    return "".join(out)


# ---- LCM types (lcm-gen --python into a temporary folder) ----
def load_lcm_types(tmp):
    files = sorted(
        os.path.join(ROOT, "lcmtypes", p, f)
        for p in os.listdir(os.path.join(ROOT, "lcmtypes"))
        if os.path.isdir(os.path.join(ROOT, "lcmtypes", p))
        for f in os.listdir(os.path.join(ROOT, "lcmtypes", p))
        if f.endswith(".lcm"))
    subprocess.run(["lcm-gen", "--python", "--ppath", tmp] + files, check=True)
    sys.path.insert(0, tmp)
    types = []
    for f in files:  # the order of tests/fuzz/CMakeLists.txt's list (sorted paths)
        pkg = os.path.basename(os.path.dirname(f))
        name = os.path.splitext(os.path.basename(f))[0]
        types.append((pkg, name, getattr(importlib.import_module(pkg + "." + name), name)))
    return types


def record(channel_index, payload):
    """One record of a node target's input (tests/fuzz/fuzz_messages.hpp)."""
    assert len(payload) < 65536
    return struct.pack("<BH", channel_index, len(payload)) + payload


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=os.path.join(ROOT, "..", "shared", "data"))
    args = ap.parse_args()
    data = os.path.abspath(args.data)
    if os.path.isdir(OUT):
        shutil.rmtree(OUT)
    rng = random.Random(27)

    # ---- CARMEN ----
    clf = os.path.join(data, "laser", "mit-csail.clf")
    write("carmen", "mit-csail-head.clf", head_lines(clf, 6))
    write("carmen", "mit-csail-flaser-odom.clf",
          head_lines(clf, 4, lambda l: l.startswith(("FLASER", "ODOM"))))
    intel = os.path.join(data, "laser", "intel-corrected.log.gz")
    write("carmen", "intel-corrected.log.gz",
          gzip.compress(head_lines(intel, 3, lambda l: l.startswith("FLASER")).encode(), mtime=0))
    aces = os.path.join(data, "laser", "aces-corrected.log.gz")
    write("carmen", "aces-corrected-2.log", head_lines(aces, 2, lambda l: l.startswith("FLASER")))
    write("carmen", "robotlaser1.log",
          "ROBOTLASER1 0 -1.5708 3.14159 0.0174533 81.9 0.01 0 5 1.0 1.1 1.2 1.3 1.4 0 "
          "0 0 0 0.1 0.2 0.3 0 0 0 0 0 1000.5 host 1.5\n"
          "ODOM 0.1 0.2 0.3 0 0 0 1000.6 host 1.6\n")
    write("carmen", "subnormal.log",
          "FLASER 3 1.0 2.0 3.0 0 0 0 9.53173e-312 0 0 1.0 host 1.0\n")

    # ---- g2o ----
    pg = os.path.join(data, "posegraph")
    write("g2o", "intel-head.g2o",
          head_lines(os.path.join(pg, "intel.g2o"), 6, lambda l: l.startswith("VERTEX")) +
          head_lines(os.path.join(pg, "intel.g2o"), 8, lambda l: l.startswith("EDGE")))
    write("g2o", "sphere-head.g2o",
          head_lines(os.path.join(pg, "sphere2500.g2o"), 4, lambda l: l.startswith("VERTEX")) +
          head_lines(os.path.join(pg, "sphere2500.g2o"), 4, lambda l: l.startswith("EDGE")))
    write("g2o", "m3500-edges-only.g2o",
          head_lines(os.path.join(pg, "M3500b.g2o"), 6, lambda l: l.startswith("EDGE")))

    # ---- map_load: [YAML length u16][map_server YAML, "@IMAGE@" = the image][PGM] ----
    def map_input(yaml, pgm):
        return struct.pack("<H", len(yaml)) + yaml.encode() + pgm
    room = bytes(0 if (x in (0, 7) or y in (0, 5)) else (205 if x == 3 else 254)
                 for y in range(6) for x in range(8))
    write("map_load", "trinary-p5.bin", map_input(
        "image: @IMAGE@\nresolution: 0.05\norigin: [-0.2, -0.15, 0.0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n", b"P5\n# fusionloc\n8 6\n255\n" + room))
    write("map_load", "scale-p2.bin", map_input(
        "image: @IMAGE@\nresolution: 0.1\norigin: [0, 0, 0]\nmode: scale\nnegate: 1\n",
        ("P2\n4 2\n255\n" + " ".join(str(v) for v in (0, 50, 128, 255, 255, 128, 50, 0)) + "\n").encode()))

    # ---- fusion_state: [mode][state] (even) or [mode][edits: offset u16, byte] (odd) of the
    # valid state the target makes itself (the layout is the C++ code's: not repeated here) ----
    def edits(*pairs):
        return b"\x01" + b"".join(struct.pack("<HB", at, v) for at, v in pairs)
    write("fusion_state", "valid.bin", edits())
    write("fusion_state", "node-count-high-byte.bin", edits((23, 0x7F)))
    write("fusion_state", "version.bin", edits((12, 3)))
    write("fusion_state", "raw-magic-only.bin", b"\x00FLFUSION")

    # ---- KITTI ----
    raw = os.path.join(data, "stereo", "kitti_raw_2011_09_26_drive_0001")
    odo = os.path.join(data, "lidar_stereo", "kitti_odometry_04_f000-050")
    with open(os.path.join(raw, "calib_cam_to_cam.txt")) as f:
        write("kitti_calib", "raw-calib_cam_to_cam.txt", b"\x00" + f.read().encode())
    with open(os.path.join(odo, "calib.txt")) as f:
        calib = f.read().encode()
    write("kitti_calib", "odometry-calib-gray.txt", b"\x01" + calib)
    write("kitti_calib", "odometry-calib-color.txt", b"\x03" + calib)
    write("kitti_times", "odometry-times.txt", b"\x00" + head_lines(os.path.join(odo, "times.txt"), 8).encode())
    write("kitti_times", "raw-timestamps.txt",
          b"\x01" + head_lines(os.path.join(raw, "image_00", "timestamps.txt"), 8).encode())
    write("kitti_poses", "odometry-poses.txt", head_lines(os.path.join(odo, "poses.txt"), 6))
    write("kitti_poses", "raw-poses.txt", head_lines(os.path.join(raw, "poses_cam0_from_oxts.txt"), 6))

    # ---- YAML options: first byte picks the struct (tests/fuzz/targets/yaml_options.cpp) ----
    cfg = os.path.join(ROOT, "config")
    for index, files in enumerate([["rbpf_slam.yaml"], ["stereo_vo.yaml"], ["fusion.yaml"], [], [],
                                   ["base_driver.yaml"], ["robot/sim.yaml", "robot/turtlebot2.yaml"]]):
        for f in files:
            with open(os.path.join(cfg, f), "rb") as fh:
                write("yaml_options", f.replace("/", "-"), bytes([index]) + fh.read())
    write("yaml_options", "carmen.yaml", b"\x03noisy_odometry: auto\nseed: 3\nnoise:\n  a1: 0.1\n")
    write("yaml_options", "kitti.yaml", b"\x04start_frame: 2\nmax_frames: 10\ncameras: gray\n")

    # ---- procman .cfg ----
    for f in sorted(os.listdir(os.path.join(cfg, "procman"))):
        with open(os.path.join(cfg, "procman", f), "rb") as fh:
            write("procman_cfg", f, fh.read())

    # ---- SCIP 2.0 (as the URG emulator answers) ----
    def cs(s):
        return chr((sum(s.encode()) & 0x3F) + 0x30)

    def enc(v, n):
        return "".join(chr(((v >> (6 * (n - 1 - i))) & 0x3F) + 0x30) for i in range(n))

    def line(s):
        return s + cs(s) + "\n"

    def scan_response(start, end, values, encoding, remaining=0):
        echo = "MD%04d%04d%02d%d%02d" % (start, end, 1, 0, remaining)
        block = "".join(enc(v, encoding) for v in values)
        out = echo + "\n" + line("99") + line(enc(123456, 4))
        for i in range(0, len(block), 64):
            out += line(block[i:i + 64])
        return out + "\n"

    vv = ("VV\n" + "00P\n" + line("VEND:Hokuyo Automatic Co.,Ltd.;") + line("PROD:SOKUIKI Sensor URG-04LX;")
          + line("SERI:H0000001;") + "\n")
    pp = "PP\n00P\n" + line("DMIN:20;") + line("DMAX:5600;") + line("ARES:1024;") + line("AMIN:44;") + \
         line("AMAX:725;") + line("AFRT:384;") + line("SCAN:600;") + "\n"
    write("scip2", "vv-pp.bin", b"\x3f" + (vv + pp).encode())
    vals = [int(1000 + 800 * math.sin(i / 9.0)) for i in range(60)]
    write("scip2", "md-scan3.bin", b"\x3f" + ("MD0044010301000\n00P\n\n" + scan_response(44, 103, vals, 3)).encode())
    write("scip2", "ms-scan2.bin", b"\x20" + scan_response(44, 83, [v % 4096 for v in vals[:40]], 2)
          .replace("MD", "MS", 1).encode())

    # ---- Kobuki feedback (as the base emulator streams it) ----
    def packet(payload):
        x = len(payload)
        for b in payload:
            x ^= b
        return bytes([0xAA, 0x55, len(payload)]) + payload + bytes([x])

    def basic(ts, left, right):
        return bytes([0x01, 15]) + struct.pack("<HBBBHHbbBBBB", ts & 0xFFFF, 0, 0, 0, left & 0xFFFF,
                                              right & 0xFFFF, 0, 0, 0, 0, 160, 0)

    stream = b""
    for k in range(12):
        stream += packet(basic(20 * k, 65500 + 30 * k, 40 * k) + bytes([0x04, 7]) + bytes(7))
    write("kobuki", "feedback.bin", b"\x5f" + stream)
    write("kobuki", "noise-then-feedback.bin", b"\x10" + bytes([0xAA, 0x55, 0x02, 0x01]) + stream[:60])
    kobuki_stream = stream

    # ---- LCM messages ----
    tmp = tempfile.mkdtemp(prefix="fl_corpus_")
    try:
        types = load_lcm_types(tmp)
        T = {pkg + "." + name: cls for pkg, name, cls in types}
        index = {pkg + "." + name: i for i, (pkg, name, _) in enumerate(types)}

        scans = [l for l in head_lines(clf, 4, lambda l: l.startswith("FLASER")).splitlines()]

        def lidar(k, beams_every=4):
            t = scans[k % len(scans)].split()
            n = int(t[1])
            m = T["bot_core.planar_lidar_t"]()
            m.utime = 1000000 + 100000 * k
            m.ranges = [float(r) for r in t[2:2 + n]][::beams_every]
            m.nranges = len(m.ranges)
            m.intensities = []
            m.nintensities = 0
            m.rad0 = -math.pi / 2
            m.radstep = math.pi / (m.nranges - 1)
            return m

        def odom(k):
            m = T["fusionloc.wheel_odometry_t"]()
            m.utime = 1000000 + 100000 * k
            m.x, m.y, m.theta, m.v = 0.05 * k, 0.0, 0.01 * k, 0.5
            return m

        def rigid(x=0.1):
            m = T["bot_core.rigid_transform_t"]()
            m.trans = [x, 0.0, 0.2]
            m.quat = [1.0, 0.0, 0.0, 0.0]
            return m

        def image(w, h, shift, seed):
            # Blocks of 4x4 random gray (corners for FAST), the right image shifted by `shift`.
            r = random.Random(seed)
            blocks = [[r.randrange(256) for _ in range((w + 8) // 4 + 1)] for _ in range(h // 4 + 1)]
            base = [[blocks[y // 4][x // 4] for x in range(w + 8)] for y in range(h)]
            m = T["bot_core.image_t"]()
            m.width, m.height, m.row_stride = w, h, w
            m.pixelformat = 1497715271  # GRAY
            m.data = bytes(base[y][x + shift] for y in range(h) for x in range(w))
            m.size = len(m.data)
            m.metadata = []
            m.nmetadata = 0
            return m

        def stereo(k, w=64, h=64):
            m = T["bot_core.images_t"]()
            m.utime = 1000000 + 100000 * k
            m.n_images = 2
            m.image_types = [0, 1]
            m.images = [image(w, h, 4, k), image(w, h, 0, k)]
            for im in m.images:
                im.utime = m.utime
            return m

        def calib(w=64, h=64):
            m = T["fusionloc.stereo_calibration_t"]()
            m.width, m.height = w, h
            m.fx = m.fy = 50.0
            m.cx, m.cy = w / 2.0, h / 2.0
            m.baseline = 0.5
            m.rectified = True
            return m

        def pose(k):
            m = T["bot_core.pose_t"]()
            m.utime = 1000000 + 100000 * k
            m.pos = [0.1 * k, 0.0, 0.0]
            m.orientation = [1.0, 0.0, 0.0, 0.0]
            return m

        def factor(k, source):
            m = T["fusionloc.relative_pose_factor_t"]()
            m.utime_i = 1000000 + 100000 * k
            m.utime_j = m.utime_i + 100000
            m.trans = [0.1, 0.0, 0.0]
            m.quat = [1.0, 0.0, 0.0, 0.0]
            m.information = [100.0 if i % 7 == 0 else 0.0 for i in range(36)]
            m.source = source
            m.is_loop_closure = False
            m.keyframe_id_i, m.keyframe_id_j = k, k + 1
            return m

        def points(k, n=20):
            m = T["fusionloc.point_cloud_t"]()
            m.utime = 1000000 + 100000 * k
            m.frame = "camera"
            m.points = [[rng.uniform(-2, 2), rng.uniform(-1, 1), rng.uniform(1, 8)] for _ in range(n)]
            m.num_points = n
            m.intensities = [0.5] * n
            m.num_intensities = n
            return m

        # Node targets (channel order of each target's .cpp).
        write("rbpf_node", "laser-odometry.bin",
              record(2, rigid().encode()) + b"".join(record(1, odom(k).encode()) + record(0, lidar(k).encode())
                                                     for k in range(4)) + record(1, odom(4).encode()))
        write("rbpf_node", "laser-only.bin", b"".join(record(0, lidar(k, 8).encode()) for k in range(3)))
        # localizer_node: the rbpf_node channels plus INITIAL_POSE (3).
        write("localizer_node", "initial-pose.bin",
              record(2, rigid().encode()) + record(3, pose(0).encode()) +
              b"".join(record(1, odom(k).encode()) + record(0, lidar(k).encode()) for k in range(4)) +
              record(1, odom(4).encode()))
        write("localizer_node", "global.bin",
              b"".join(record(1, odom(k).encode()) + record(0, lidar(k, 8).encode()) for k in range(3)))
        write("stereo_vo_node", "calib-stereo.bin",
              record(1, calib().encode()) + record(2, rigid(0.0).encode()) +
              b"".join(record(0, stereo(k).encode()) for k in range(3)))
        def scan3d(k, n=300):
            # Points 3-6 m in front of a camera mounted like the laser (both rigid(0.0)).
            m = T["fusionloc.laser_scan_3d_t"]()
            m.utime = 1000000 + 100000 * k - 2000
            m.frame = "laser"
            z = [rng.uniform(3, 6) for _ in range(n)]
            m.x = [zi * rng.uniform(-0.6, 0.6) for zi in z]
            m.y = [zi * rng.uniform(-0.6, 0.6) for zi in z]
            m.z = z
            m.intensity = [0.5] * n
            m.num_points = n
            return m

        # stereo_vo_node in the laser-aided mode: LASER_3D (3) before each frame, its mounting (4).
        write("stereo_vo_node", "laser-aided.bin",
              record(1, calib().encode()) + record(2, rigid(0.0).encode()) + record(4, rigid(0.0).encode()) +
              b"".join(record(3, scan3d(k).encode()) + record(0, stereo(k).encode()) for k in range(3)))
        # stereo_vo_node with the odometry prior: ODOMETRY (5) before each frame, one out of order.
        write("stereo_vo_node", "odometry-prior.bin",
              record(1, calib().encode()) + record(2, rigid(0.0).encode()) +
              b"".join(record(5, odom(k).encode()) + record(0, stereo(k).encode()) for k in range(3)) +
              record(5, odom(1).encode()))
        write("stereo_vo_node", "stereo-before-calib.bin",
              record(0, stereo(0, 32, 24).encode()) + record(1, calib(32, 24).encode()) + record(0, stereo(1, 32, 24).encode()))
        write("fusion_node", "poses-factors.bin",
              record(5, rigid(0.0).encode()) +
              b"".join(record(0, pose(k).encode()) + record(3, odom(k).encode()) for k in range(4)) +
              record(1, factor(0, 0).encode()) + record(2, factor(1, 1).encode()) + record(4, points(1).encode()) +
              record(0, pose(5).encode()))

        # base_driver: BASE_COMMAND (even selector) and serial bytes (odd).
        def command(v, omega):
            m = T["fusionloc.base_command_t"]()
            m.utime, m.v, m.omega = 1000000, v, omega
            return m

        half = len(kobuki_stream) // 2
        write("base_driver", "command-feedback.bin",
              record(0, command(0.2, 0.1).encode()) + record(1, kobuki_stream[:half]) +
              record(0, command(0.0, 0.5).encode()) + record(1, kobuki_stream[half:]))
        write("base_driver", "feedback-only.bin", record(1, kobuki_stream))

        # lcm_decode: a byte for the type, then the message.
        def sample(name):
            return {
                "bot_core.planar_lidar_t": lambda: lidar(0, 16),
                "bot_core.images_t": lambda: stereo(0, 8, 6),
                "bot_core.image_t": lambda: image(8, 6, 0, 1),
                "bot_core.pose_t": lambda: pose(1),
                "bot_core.rigid_transform_t": rigid,
                "fusionloc.wheel_odometry_t": lambda: odom(1),
                "fusionloc.stereo_calibration_t": calib,
                "fusionloc.relative_pose_factor_t": lambda: factor(1, 0),
                "fusionloc.point_cloud_t": lambda: points(1, 4),
            }.get(name, lambda: T[name]())()

        meta = T["bot_core.image_metadata_t"]()
        meta.key = "exposure"
        meta.value = b"12.5"
        meta.n = len(meta.value)
        samples_by_type = {"bot_core.image_metadata_t": meta}
        decode_names = sorted(index)

        def write_decode_seeds(extra):
            samples_by_type.update(extra)
            for name in decode_names:
                try:
                    payload = (samples_by_type[name] if name in samples_by_type else sample(name)).encode()
                except Exception:  # a type whose defaults do not encode (None arrays): skip
                    continue
                write("lcm_decode", name + ".bin", bytes([index[name]]) + payload)

        # lcm_log: small LCM log files (lcm-logger's format).
        def event(num, utime, channel, data):
            return struct.pack(">IqqII", 0xEDA1DA01, num, utime, len(channel), len(data)) + channel.encode() + data

        log = b"".join(event(k, 1000 + k, ch, msg.encode()) for k, (ch, msg) in enumerate(
            [("LASER", lidar(0, 16)), ("ODOMETRY", odom(0)), ("RBPF_POSE", pose(0)),
             ("STEREO_CALIBRATION", calib()), ("LASER", lidar(1, 16))]))
        write("lcm_log", "small.lcmlog", log)
        write("lcm_log", "truncated.lcmlog", log[:-7])
        write("lcm_log", "corrupt-middle.lcmlog", log[:90] + b"\x00" * 11 + log[101:])

        # procman_orders: mode 0 an envelope (never valid), mode 1 orders the harness signs.
        orders = T["bot_procman.orders2_t"]()
        orders.utime = 1700000000000000
        orders.host = "robot"
        orders.sheriff_name = "fuzz"
        cmd = T["bot_procman.command2_t"]()
        cmd.exec_str = "/bin/true"
        cmd.command_name = "true"
        cmd.group = "g"
        cmd.auto_respawn = False
        cmd.stop_signal = 2
        cmd.stop_time_allowed = 1.0
        cmd.num_options = 0
        cmd.option_names = []
        cmd.option_values = []
        dc = T["bot_procman.sheriff_cmd2_t"]()
        dc.cmd = cmd
        dc.sheriff_id = 1
        dc.desired_runid = 1
        dc.force_quit = 0
        orders.cmds = [dc]
        orders.ncmds = 1
        orders.num_options = 0
        orders.option_names = []
        orders.option_values = []
        encoded = orders.encode()
        write("procman_orders", "signed-orders.bin", b"\x01" + encoded)
        env = T["fusionloc.procman_signed_orders_t"]()
        env.utime = 1700000000000000
        env.sheriff_id = "fuzz@host"
        env.key_id = "0123456789abcdef"
        env.counter = 1
        env.orders = encoded
        env.orders_size = len(encoded)
        env.mac = bytes(32)
        write("procman_orders", "forged-envelope.bin", b"\x00" + env.encode())
        write_decode_seeds({"fusionloc.procman_signed_orders_t": env, "bot_procman.orders2_t": orders,
                            "bot_procman.command2_t": cmd, "bot_procman.sheriff_cmd2_t": dc})
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    total = sum(os.path.getsize(os.path.join(dp, f)) for dp, _, fs in os.walk(OUT) for f in fs)
    count = sum(len(fs) for _, _, fs in os.walk(OUT))
    print("wrote %d seeds, %.1f KB, in %s" % (count, total / 1024.0, OUT))


if __name__ == "__main__":
    main()
