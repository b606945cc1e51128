#!/usr/bin/python3
"""fl-viewer in a real browser: headless Chromium driven by Selenium (Debian's chromium,
chromium-driver, python3-selenium).

  viewer_browser_test.py CASE --bin DIR --tests DIR --source DIR --artifacts DIR
  CASE: live  the page loads without console errors, its WebSocket connects, the known grid
              published on RBPF_MAP is drawn with the right cells at the right place (canvas
              pixels read back), the published trajectory is drawn.
        demo  a short run of config/procman/sim.cfg's demo beside the viewer: the process
              panel lists its processes; a screenshot of the final view (artifact).
        log   fl-viewer --log: moving the time slider moves the robot; play moves it on.
Exit 77 (ctest: skipped) when Chromium, its driver or Selenium is missing, or there is no
UDP multicast for live LCM; 1 on a failure.
"""
import argparse
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time

SKIP = 77


def skip(why):
    print("SKIPPED: " + why)
    sys.exit(SKIP)


def fail(why):
    print("FAILED: " + why)
    sys.exit(1)


def check(cond, why):
    if not cond:
        fail(why)
    print("ok: " + why)


def need_browser():
    for prog in ("chromium", "chromedriver"):
        if not shutil.which(prog):
            skip(prog + " not found: install Debian's chromium and chromium-driver "
                 "(./fusionloc setup)")
    try:
        import selenium  # noqa: F401
    except ImportError:
        skip("python3-selenium not found (./fusionloc setup)")


def multicast_ok(port):
    """True if a UDP multicast datagram to ourselves comes back (live LCM needs it)."""
    group = "239.255.76.67"
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    try:
        rx.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        rx.bind(("", port))
        mreq = socket.inet_aton(group) + socket.inet_aton("0.0.0.0")
        rx.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, mreq)
        rx.settimeout(1.0)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
        tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
        tx.sendto(b"ping", (group, port))
        return rx.recv(16) == b"ping"
    except OSError:
        return False
    finally:
        rx.close()


class Viewer:
    """fl-viewer on a free port; its address is read from its log."""

    def __init__(self, args, extra, log_path):
        self.log_path = log_path
        self.log = open(log_path, "w")
        self.proc = subprocess.Popen([os.path.join(args.bin, "fl-viewer"), "--port", "0"] + extra,
                                     stdout=self.log, stderr=subprocess.STDOUT)
        self.url = None
        deadline = time.time() + 20
        while time.time() < deadline and self.url is None:
            if self.proc.poll() is not None:
                fail("fl-viewer exited with %d: %s" % (self.proc.returncode, self.text()))
            m = re.search(r"open (http://127\.0\.0\.1:\d+/\S*)", self.text())
            if m:
                self.url = m.group(1)
            time.sleep(0.1)
        if self.url is None:
            fail("fl-viewer printed no address: " + self.text())

    def text(self):
        with open(self.log_path) as f:
            return f.read()

    def stop(self):
        self.proc.terminate()
        try:
            rc = self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            fail("fl-viewer did not stop on SIGTERM")
        self.log.close()
        return rc


def browser(width=1280, height=800):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    opts = webdriver.ChromeOptions()
    for a in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
              "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
              "--window-size=%d,%d" % (width, height)):
        opts.add_argument(a)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    try:
        return webdriver.Chrome(service=Service(shutil.which("chromedriver")), options=opts)
    except Exception as e:  # a browser that cannot start here is a skip, not a failure
        skip("headless Chromium does not start: %s" % str(e).splitlines()[0])


def wait_for(driver, js, what, timeout=20):
    deadline = time.time() + timeout
    value = None
    while time.time() < deadline:
        value = driver.execute_script("return " + js)
        if value:
            return value
        time.sleep(0.1)
    fail("timed out waiting for %s (%s = %r)" % (what, js, value))


def console_errors(driver):
    return [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]


def open_page(driver, url):
    driver.get(url)
    wait_for(driver, "window.flViewer && window.flViewer.state.connected", "the WebSocket")
    print("ok: page loaded, WebSocket connected")


def near(rgba, rgb, tol):
    return all(abs(rgba[i] - rgb[i]) <= tol for i in range(3))


def case_live(args, tmp):
    desc = json.loads(subprocess.check_output([os.path.join(args.tests, "viewer_fixture"),
                                               "describe"]))
    port = 7300 + os.getpid() % 200
    if not multicast_ok(port):
        skip("no UDP multicast on this machine (ip link set lo multicast on; "
             "ip route add 224.0.0.0/4 dev lo)")
    url = "udpm://239.255.76.67:%d?ttl=0" % port
    viewer = Viewer(args, ["--lcm-url", url], os.path.join(tmp, "viewer.log"))
    driver = browser()
    try:
        open_page(driver, viewer.url)
        pub = subprocess.Popen([os.path.join(args.tests, "viewer_fixture"), "publish", url, "6"])
        wait_for(driver, "flViewer.state.grid", "the grid from RBPF_MAP")
        wait_for(driver, "flViewer.state.trajectories.FUSED_TRAJECTORY", "the trajectory")
        g = driver.execute_script("return flViewer.state.grid")
        for k in ("resolution", "width", "height", "origin_x", "origin_y"):
            check(abs(g[k] - desc["grid"][k]) < 1e-9, "grid %s = %s" % (k, g[k]))
        # The grid alone, seen from the top, fitted to the canvas.
        driver.execute_script("flViewer.setView('top'); flViewer.showOnly(['grid']); flViewer.fit()")
        for p in desc["probes"]:
            px, py = driver.execute_script("return flViewer.worldToCanvas(%f, %f)" % (p["x"], p["y"]))
            rgba = driver.execute_script("return flViewer.readPixel(%f, %f)" % (px, py))
            v = p["value"]
            want = 128 if v < 0 else round(255 - 2.55 * v)
            check(near(rgba, (want, want, want), 4),
                  "cell row %d col %d (%g, %g) = %d%%: pixel (%.0f, %.0f) is %s, want gray %d"
                  % (p["row"], p["col"], p["x"], p["y"], v, px, py, rgba[:3], want))
        # Just below the grid (fitted to the canvas' width, it has room above and below): the
        # background.
        px, py = driver.execute_script("return flViewer.worldToCanvas(%f, %f)"
                                       % (desc["grid"]["origin_x"] + 1, desc["grid"]["origin_y"] - 0.3))
        rgba = driver.execute_script("return flViewer.readPixel(%f, %f)" % (px, py))
        check(near(rgba, (0x1e, 0x24, 0x30), 4), "below the grid is background: %s at (%.0f, %.0f)"
              % (rgba[:3], px, py))
        # The trajectory, alone: its colour along the line, not off it.
        driver.execute_script("flViewer.showOnly(['FUSED_TRAJECTORY'])")
        t = desc["trajectory"]
        for f in (0.25, 0.5, 0.75):
            x, y = t["x0"] + f * (t["x1"] - t["x0"]), t["y0"] + f * (t["y1"] - t["y0"])
            px, py = driver.execute_script("return flViewer.worldToCanvas(%f, %f)" % (x, y))
            region = driver.execute_script("return flViewer.readRegion(%f, %f, 2)" % (px, py))
            check(any(near(c, (0x00, 0xff, 0xaa), 40) for c in region),
                  "trajectory drawn at %.0f%% of its length (%g, %g)" % (100 * f, x, y))
        x, y = t["x0"] + 0.5 * (t["x1"] - t["x0"]), t["y0"] + 0.5 * (t["y1"] - t["y0"]) + 2.0
        px, py = driver.execute_script("return flViewer.worldToCanvas(%f, %f)" % (x, y))
        region = driver.execute_script("return flViewer.readRegion(%f, %f, 2)" % (px, py))
        check(not any(near(c, (0x00, 0xff, 0xaa), 40) for c in region), "nothing 2 m off the trajectory")
        # STATUS comes about once a second: wait for it (on a loaded machine it can come after
        # the drawing checks above).
        wait_for(driver, "flViewer.state.processes.some(function (p) "
                 "{ return p.process === 'fl-fixture'; })", "the fixture's STATUS", timeout=10)
        names = driver.execute_script(
            "return flViewer.state.processes.map(function (p) { return p.process; })")
        check("fl-fixture" in names, "process panel lists the fixture's STATUS: %s" % names)
        rates = driver.execute_script("return flViewer.state.rates.map(function (c) { return c.name; })")
        check("RBPF_MAP" in rates and "STATUS_FL_VIEWER" not in rates, "channel rates: %s" % rates)
        driver.execute_script("flViewer.showOnly(['grid', 'FUSED_TRAJECTORY'])")
        driver.save_screenshot(os.path.join(args.artifacts, "viewer_live.png"))
        errors = console_errors(driver)
        check(not errors, "no console error: %s" % errors)
        pub.wait(20)
    finally:
        driver.quit()
        rc = viewer.stop()
    check(rc == 0, "fl-viewer exits 0 on SIGTERM")
    return 0


def case_demo(args, tmp):
    port = 7500 + os.getpid() % 200
    if not multicast_ok(port):
        skip("no UDP multicast on this machine")
    url = "udpm://239.255.76.67:%d?ttl=0&recv_buf_size=16777216" % port
    viewer = Viewer(args, ["--lcm-url", url], os.path.join(tmp, "viewer.log"))
    driver = browser()
    try:
        open_page(driver, viewer.url)
        cfg = os.path.join(args.source, "config", "procman", "sim.cfg")
        sheriff = subprocess.Popen(
            [os.path.join(args.bin, "fl-procman-sheriff"), "--lone-ranger", cfg, "demo",
             "--quit-after-script", "--status-period", "0", "--log-dir", tmp, "--lcm-url", url,
             "--var", "BIN=" + args.bin, "--var", "CONFIG=" + os.path.join(args.source, "config"),
             "--var", "RUN_DIR=" + tmp, "--var", "WORLD=paper", "--var", "RATE=1",
             "--var", "DURATION=12", "--var", "LCM_URL=" + url],
            stdin=subprocess.DEVNULL, stdout=open(os.path.join(tmp, "sheriff.out"), "w"),
            stderr=subprocess.STDOUT)
        want = ["fl-sim", "fl-rbpf-slam", "fl-stereo-vo", "fl-fusion"]
        wait_for(driver, "(function () { var n = flViewer.state.processes.map(function (p) "
                 "{ return p.process; }); return %s.every(function (w) { return n.indexOf(w) >= 0; }); })()"
                 % json.dumps(want), "the run's processes in the panel", timeout=40)
        print("ok: process panel lists %s" % want)
        cmds = wait_for(driver, "(function () { var c = []; flViewer.state.deputies.forEach("
                        "function (d) { d.commands.forEach(function (x) { c.push(x.name); }); });"
                        " return c.length >= 5 ? c : null; })()", "the deputy's commands", timeout=20)
        check(all(n in cmds for n in ("logger", "rbpf_slam", "stereo_vo", "fusion", "sim")),
              "deputy commands listed: %s" % cmds)
        text = driver.find_element("id", "processes").text
        check("fl-rbpf-slam" in text and "fl-fusion" in text, "the panel's table shows them")
        rc = sheriff.wait(120)
        check(rc == 0, "the short demo ran (sheriff exit %d)" % rc)
        wait_for(driver, "flViewer.state.grid", "the RBPF map")
        wait_for(driver, "flViewer.state.trails.FUSED_POSE > 10", "the fused trail")
        wait_for(driver, "flViewer.state.clouds.VO_POINTS > 0", "the VO cloud")
        check(driver.execute_script("return document.getElementById('fusion').textContent")
              .find("nodes") >= 0, "fusion summary panel filled")
        driver.execute_script("flViewer.setView('3d'); flViewer.fit()")
        driver.save_screenshot(os.path.join(args.artifacts, "viewer_demo_3d.png"))
        driver.execute_script("flViewer.setView('top'); flViewer.fit()")
        time.sleep(0.3)
        driver.save_screenshot(os.path.join(args.artifacts, "viewer_demo.png"))
        print("screenshot: " + os.path.join(args.artifacts, "viewer_demo.png"))
        errors = console_errors(driver)
        check(not errors, "no console error: %s" % errors)
    finally:
        driver.quit()
        rc = viewer.stop()
    check(rc == 0, "fl-viewer exits 0 on SIGTERM")
    return 0


def case_log(args, tmp):
    log = os.path.join(tmp, "drive.lcmlog")
    subprocess.check_call([os.path.join(args.tests, "viewer_fixture"), "log", log])
    desc = json.loads(subprocess.check_output([os.path.join(args.tests, "viewer_fixture"),
                                               "describe"]))
    viewer = Viewer(args, ["--log", log, "--paused"], os.path.join(tmp, "viewer.log"))
    driver = browser()
    try:
        open_page(driver, viewer.url)
        wait_for(driver, "flViewer.state.clock", "the log clock")
        check(driver.execute_script("return !document.getElementById('player').hidden"),
              "the time slider is shown in log mode")
        x0 = wait_for(driver, "flViewer.state.poses.FUSED_POSE", "the robot")[0]
        check(abs(x0) < 1e-6, "paused at the start: robot at x = %g" % x0)
        # Move the slider to 6.5 s as a user does (value + change event).
        driver.execute_script("var s = document.getElementById('slider'); s.value = '6.5';"
                              "s.dispatchEvent(new Event('input')); s.dispatchEvent(new Event('change'));")
        wait_for(driver, "Math.abs(flViewer.state.poses.FUSED_POSE[0] - 6.5) < 1e-6",
                 "the robot at x = 6.5 after the seek")
        print("ok: slider at 6.5 s moved the robot to x = 6.5")
        driver.execute_script("flViewer.setView('top'); flViewer.showOnly(['FUSED_POSE']); flViewer.fit()")
        px, py = driver.execute_script("return flViewer.worldToCanvas(6.55, 0)")
        region = driver.execute_script("return flViewer.readRegion(%f, %f, 2)" % (px, py))
        check(any(near(c, (0x33, 0xdd, 0x55), 30) for c in region), "the robot's arrow drawn at x = 6.5")
        # Seek back: the trail is rebuilt, not doubled.
        n_at_65 = driver.execute_script("return flViewer.state.trails.FUSED_POSE")
        driver.execute_script("var s = document.getElementById('slider'); s.value = '3';"
                              "s.dispatchEvent(new Event('change'));")
        wait_for(driver, "Math.abs(flViewer.state.poses.FUSED_POSE[0] - 3) < 1e-6", "x = 3 after seeking back")
        n_at_3 = driver.execute_script("return flViewer.state.trails.FUSED_POSE")
        check(n_at_3 < n_at_65, "trail rebuilt on seeking back (%d < %d poses)" % (n_at_3, n_at_65))
        # Play at 5x: the robot moves on, up to the end of the drive.
        driver.execute_script("var s = document.getElementById('speed'); s.value = '5';"
                              "s.dispatchEvent(new Event('change'));")
        driver.find_element("id", "btn-play").click()
        wait_for(driver, "flViewer.state.poses.FUSED_POSE[0] > 5", "the robot moving on while playing")
        end_x = desc["drive"]["duration_s"]
        wait_for(driver, "Math.abs(flViewer.state.poses.FUSED_POSE[0] - %f) < 1e-6 && "
                 "!flViewer.state.clock.playing" % end_x, "the end of the log", timeout=20)
        print("ok: played to the end (x = %g) and stopped" % end_x)
        check(driver.execute_script("return flViewer.state.grid !== null"), "grid shown in log mode")
        driver.save_screenshot(os.path.join(args.artifacts, "viewer_log.png"))
        errors = console_errors(driver)
        check(not errors, "no console error: %s" % errors)
    finally:
        driver.quit()
        rc = viewer.stop()
    check(rc == 0, "fl-viewer exits 0 on SIGTERM")
    return 0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("case", choices=["live", "demo", "log"])
    ap.add_argument("--bin", required=True)
    ap.add_argument("--tests", required=True)
    ap.add_argument("--source", required=True)
    ap.add_argument("--artifacts", required=True)
    args = ap.parse_args()
    need_browser()
    os.makedirs(args.artifacts, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="fl_viewer_") as tmp:
        try:
            return {"live": case_live, "demo": case_demo, "log": case_log}[args.case](args, tmp)
        except SystemExit:
            for f in ("viewer.log", "sheriff.out"):
                p = os.path.join(tmp, f)
                if os.path.exists(p):
                    print("--- " + f)
                    print(open(p).read()[-3000:])
            raise


if __name__ == "__main__":
    sys.exit(main())
