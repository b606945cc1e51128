#!/usr/bin/python3
"""What fl-viewer costs during the demo: runs config/procman/sim.cfg's demo script twice
(--duration S of the paper world, real time), without and with fl-viewer and a headless
Chromium showing its page, and prints the CPU time of every process (the sheriff's report) and
the viewer's own, and the estimators' CPU per input message.

  tools/viewer_cost/viewer_cost.py [--duration 30] [--bin build/bin]
CPU times are the sheriff's (0.1 s resolution). Needs UDP multicast, chromium, chromium-driver and python3-selenium. Takes about 2 x (S + 15) s.
"""
import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def cpu_seconds(pid):
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run(args, view, port):
    url = "udpm://239.255.76.67:%d?ttl=0&recv_buf_size=16777216" % port
    tmp = tempfile.mkdtemp(prefix="fl_viewer_cost_")
    viewer = driver = None
    if view:
        viewer = subprocess.Popen([os.path.join(args.bin, "fl-viewer"), "--lcm-url", url, "--port", "0",
                                   "--config", os.path.join(ROOT, "config", "viewer.yaml")],
                                  stdout=open(os.path.join(tmp, "viewer.log"), "w"), stderr=subprocess.STDOUT)
        address = None
        for _ in range(100):
            m = re.search(r"open (http://\S+)", open(os.path.join(tmp, "viewer.log")).read())
            if m:
                address = m.group(1)
                break
            time.sleep(0.1)
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
        o = webdriver.ChromeOptions()
        for a in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader",
                  "--enable-unsafe-swiftshader", "--window-size=1280,800"):
            o.add_argument(a)
        driver = webdriver.Chrome(service=Service(shutil.which("chromedriver")), options=o)
        driver.get(address)
    cfg = os.path.join(ROOT, "config", "procman", "sim.cfg")
    rc = subprocess.call(
        [os.path.join(args.bin, "fl-procman-sheriff"), "--lone-ranger", cfg, "demo", "--quit-after-script",
         "--status-period", "0", "--log-dir", tmp, "--report", os.path.join(tmp, "processes.txt"),
         "--lcm-url", url, "--var", "BIN=" + args.bin, "--var", "CONFIG=" + os.path.join(ROOT, "config"),
         "--var", "RUN_DIR=" + tmp, "--var", "WORLD=paper", "--var", "RATE=1",
         "--var", "DURATION=%g" % args.duration, "--var", "LCM_URL=" + url],
        stdin=subprocess.DEVNULL, stdout=open(os.path.join(tmp, "sheriff.out"), "w"), stderr=subprocess.STDOUT)
    if rc != 0:
        sys.exit("the demo failed (sheriff exit %d); see %s" % (rc, tmp))
    viewer_cpu = None
    if view:
        viewer_cpu = cpu_seconds(viewer.pid)
        frames = driver.execute_script("return flViewer.state.frames")
        driver.quit()
        viewer.terminate()
        viewer.wait(10)
        print("  browser received %d frames" % frames)
    cpu = {}
    for line in open(os.path.join(tmp, "processes.txt")).read().splitlines()[1:]:
        f = line.split()
        if len(f) >= 7 and f[2] != "0":
            cpu[f[0]] = float(f[5])
    counts = {}
    info = subprocess.run([os.path.join(args.bin, "fl-log-info"), os.path.join(tmp, "run.lcmlog")],
                          capture_output=True, text=True).stdout
    for line in info.splitlines():
        f = line.split()
        if len(f) >= 3 and f[0] in ("LASER", "STEREO", "RBPF_POSE") and f[2].isdigit():
            counts[f[0]] = int(f[2])
    shutil.rmtree(tmp, ignore_errors=True)
    return cpu, viewer_cpu, counts


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=30)
    ap.add_argument("--bin", default=os.path.join(ROOT, "build", "bin"))
    args = ap.parse_args()
    port = 7600 + os.getpid() % 100
    print("without the viewer:")
    base, _, n0 = run(args, False, port)
    print("with fl-viewer and a browser on its page:")
    view, vcpu, n1 = run(args, True, port + 1)
    print("\n| process | CPU without viewer [s] | CPU with viewer [s] |")
    print("|---|---:|---:|")
    for k in sorted(base):
        print("| %s | %.2f | %.2f |" % (k, base[k], view.get(k, float("nan"))))
    print("| fl-viewer | - | %.2f (%.1f %% of a core) |" % (vcpu, 100 * vcpu / args.duration))
    for name, ch in (("estimators/rbpf_slam", "LASER"), ("estimators/stereo_vo", "STEREO"),
                     ("fusion", "RBPF_POSE")):
        if name in base and n0.get(ch) and n1.get(ch):
            print("%s: %.2f ms CPU per %s message without, %.2f ms with the viewer (%d / %d messages)"
                  % (name, 1000 * base[name] / n0[ch], ch, 1000 * view[name] / n1[ch], n0[ch], n1[ch]))


if __name__ == "__main__":
    main()
