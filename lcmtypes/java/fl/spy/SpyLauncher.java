// fl.spy.SpyLauncher: Debian's lcm-spy (LCM 1.3.1) with a UDP receive buffer large enough for
// the project's stereo pairs, started by `./fusionloc spy`.
//
// Why: LCM 1.3.1's Java UDPMulticastProvider reads only "network" and "ttl" from the LCM URL;
// it ignores recv_buf_size and never calls setReceiveBufferSize, so lcm-spy's socket keeps the
// kernel default (net.core.rmem_default: 212992 bytes of kernel memory, which Java reports as
// SO_RCVBUF 106496). One 640x480 stereo pair (~600 KB, ~10 UDP fragments) does not fit: the
// kernel drops fragments and most STEREO messages never reassemble (lcm-spy showed about 1 in
// 24). The C++ processes are not affected.
//
// How: this class builds lcm-spy's own window (lcm.spy.Spy, public constructor) and then raises
// SO_RCVBUF of the multicast socket of every UDP provider of that Spy's LCM instance. LCM 1.3.1
// offers no public way to reach that socket or to hand LCM a socket of our own (Spy.lcm,
// LCM.providers and UDPMulticastProvider.sock are package-private), so it uses reflection;
// every class involved is on the class path (one unnamed module), so no --add-opens is needed.
// If a later LCM renames those fields, the launcher says so and runs lcm-spy unchanged.
//
// --count-seconds N: after N seconds print, per channel, lcm-spy's own table (messages
// received, undecodable) and exit; a test checks that every STEREO message of a log arrives.
package fl.spy;

import java.awt.Component;
import java.awt.Container;
import java.awt.Frame;
import java.io.BufferedReader;
import java.io.IOException;
import java.lang.reflect.Field;
import java.net.DatagramSocket;
import java.nio.file.Files;
import java.nio.file.Paths;
import java.util.ArrayList;
import java.util.List;
import javax.swing.JTable;
import javax.swing.SwingUtilities;
import javax.swing.table.TableModel;

public final class SpyLauncher {
  // The project's receive buffer (the C++ processes' recv_buf_size in the default LCM URL).
  static final int kDefaultRecvBufSize = 16 * 1024 * 1024;

  private SpyLauncher() {}

  static void usage() {
    System.out.println(
        "usage: fl.spy.SpyLauncher [--lcm-url=URL] [--recv-buf-size BYTES] [--count-seconds N]\n"
        + "Debian's lcm-spy with the UDP receive buffer raised (LCM 1.3.1's Java side ignores\n"
        + "recv_buf_size in the URL, so large messages such as stereo pairs lose fragments).\n"
        + "  --lcm-url=URL         LCM URL (default: $LCM_DEFAULT_URL, else LCM's default)\n"
        + "  --recv-buf-size B     SO_RCVBUF to ask for, bytes (default: recv_buf_size of the\n"
        + "                        URL, else " + kDefaultRecvBufSize + "; 0 keeps the kernel's)\n"
        + "  --count-seconds N     print lcm-spy's per-channel counts after N s and exit\n"
        + "                        (still needs a display: xvfb-run -a on a headless machine)");
  }

  static int fail(int code, String message) {
    System.err.println("fl-spy: error: " + message);
    return code;
  }

  public static void main(String[] args) {
    int code = run(args);
    // -1: lcm-spy's window is up; its own threads run until the window is closed.
    if (code >= 0) System.exit(code);
  }

  // The exit code, or -1 when lcm-spy's window runs on.
  static int run(String[] args) {
    String url = null;
    Integer recvBuf = null;
    double countSeconds = -1;
    try {
      for (int i = 0; i < args.length; i++) {
        String a = args[i];
        if (a.equals("-h") || a.equals("--help")) {
          usage();
          return 0;
        } else if (a.startsWith("--lcm-url=")) {
          url = a.substring("--lcm-url=".length());
        } else if (a.equals("--lcm-url") || a.equals("-l")) {
          url = value(args, ++i, a);
        } else if (a.equals("--recv-buf-size")) {
          recvBuf = Integer.parseInt(value(args, ++i, a));
          if (recvBuf < 0) throw new IllegalArgumentException("--recv-buf-size must be >= 0");
        } else if (a.equals("--count-seconds")) {
          countSeconds = Double.parseDouble(value(args, ++i, a));
          if (!(countSeconds > 0)) {
            throw new IllegalArgumentException("--count-seconds must be > 0");
          }
        } else {
          throw new IllegalArgumentException("unknown option '" + a + "' (see --help)");
        }
      }
    } catch (NumberFormatException e) {
      return fail(2, "bad number: " + e.getMessage() + " (see --help)");
    } catch (IllegalArgumentException e) {
      return fail(2, e.getMessage());
    }
    if (url == null) url = System.getenv("LCM_DEFAULT_URL");
    if (recvBuf == null) {
      int fromUrl = url == null ? -1 : new lcm.lcm.URLParser(url).get("recv_buf_size", -1);
      recvBuf = fromUrl >= 0 ? fromUrl : kDefaultRecvBufSize;
    }

    lcm.spy.Spy spy;
    try {
      spy = new lcm.spy.Spy(url);
    } catch (java.awt.HeadlessException e) {
      return fail(1, "lcm-spy needs a display (DISPLAY is unset or unusable); on a headless "
                     + "machine run it under a virtual one: xvfb-run -a ./fusionloc spy");
    } catch (IOException | RuntimeException e) {
      return fail(1, "cannot open LCM on " + (url == null ? "the default URL" : url) + ": " + e
                     + " (for udpm:// on this host: ip link set lo multicast on; "
                     + "ip route add 224.0.0.0/4 dev lo)");
    }
    raiseReceiveBuffers(spy, recvBuf);

    if (countSeconds < 0) return -1;
    System.out.println("fl-spy: counting for " + countSeconds + " s");
    System.out.flush();
    try {
      Thread.sleep((long) (countSeconds * 1000.0));
      final List<String> lines = new ArrayList<>();
      final String[] error = {null};
      SwingUtilities.invokeAndWait(() -> error[0] = readTable(lines));
      if (error[0] != null) return fail(1, error[0]);
      System.out.println("fl-spy: lcm-spy's counts after " + countSeconds + " s ("
                         + lines.size() + " channels):");
      for (String l : lines) System.out.println(l);
      System.out.flush();
      return 0;
    } catch (Exception e) {
      return fail(1, "counting failed: " + e);
    }
  }

  static String value(String[] args, int i, String option) {
    if (i >= args.length) throw new IllegalArgumentException(option + " needs a value");
    return args[i];
  }

  static Object field(Object owner, Class<?> cls, String name) throws ReflectiveOperationException {
    Field f = cls.getDeclaredField(name);
    f.setAccessible(true);
    return f.get(owner);
  }

  // net.core.rmem_max, or -1 if unknown. (Read by line: readAllBytes trusts the size /proc
  // reports and returns a truncated value.)
  static long rmemMax() {
    try (BufferedReader r = Files.newBufferedReader(Paths.get("/proc/sys/net/core/rmem_max"))) {
      String line = r.readLine();
      return line == null ? -1 : Long.parseLong(line.trim());
    } catch (IOException | NumberFormatException e) {
      return -1;
    }
  }

  // Sets SO_RCVBUF of each udpm provider's socket and says what the kernel really gave.
  static void raiseReceiveBuffers(lcm.spy.Spy spy, int asked) {
    List<DatagramSocket> sockets = new ArrayList<>();
    try {
      lcm.lcm.LCM lcm = (lcm.lcm.LCM) field(spy, lcm.spy.Spy.class, "lcm");
      for (Object p : (List<?>) field(lcm, lcm.lcm.LCM.class, "providers")) {
        if (p instanceof lcm.lcm.UDPMulticastProvider) {
          sockets.add((DatagramSocket) field(p, lcm.lcm.UDPMulticastProvider.class, "sock"));
        }
      }
    } catch (ReflectiveOperationException | ClassCastException e) {
      System.err.println("fl-spy: warning: cannot reach LCM's UDP socket in this LCM version ("
                         + e + "); lcm-spy keeps the kernel's default receive buffer and may "
                         + "drop large messages");
      return;
    }
    if (sockets.isEmpty()) {
      System.out.println("fl-spy: no udpm:// provider; receive buffer not changed");
      return;
    }
    long max = rmemMax();
    for (DatagramSocket s : sockets) {
      try {
        int before = s.getReceiveBufferSize();
        if (asked > 0) s.setReceiveBufferSize(asked);
        int now = s.getReceiveBufferSize();
        // The kernel caps the request at rmem_max (and reserves twice the capped size for its
        // bookkeeping; Java reports the capped size, like the C++ side's recv_buf_size).
        String msg = "fl-spy: UDP receive buffer " + now + " bytes (kernel default " + before
                     + "; asked " + asked + (asked == 0 ? " = keep the default" : "")
                     + "; net.core.rmem_max " + (max < 0 ? "unknown" : Long.toString(max)) + ")";
        System.out.println(msg);
        if (asked > 0 && max >= 0 && max < asked) {
          System.out.println("fl-spy: note: the kernel caps the buffer at net.core.rmem_max; for "
                             + "the full " + asked + " bytes run as root: sysctl -w "
                             + "net.core.rmem_max=" + asked);
        }
      } catch (IOException e) {
        System.err.println("fl-spy: warning: cannot set the receive buffer: " + e);
      }
    }
  }

  static JTable findTable(Component c) {
    if (c instanceof JTable) return (JTable) c;
    if (c instanceof Container) {
      for (Component child : ((Container) c).getComponents()) {
        JTable t = findTable(child);
        if (t != null) return t;
      }
    }
    return null;
  }

  static int column(TableModel m, String name) {
    for (int c = 0; c < m.getColumnCount(); c++) {
      if (name.equals(m.getColumnName(c))) return c;
    }
    return -1;
  }

  // lcm-spy's channel table, one line per channel:
  // "channel NAME messages N undecodable E type T". Runs on the Swing thread.
  static String readTable(List<String> lines) {
    JTable table = null;
    for (Frame f : Frame.getFrames()) {
      if ("LCM Spy".equals(f.getTitle())) table = findTable(f);
      if (table != null) break;
    }
    if (table == null) return "lcm-spy's window (\"LCM Spy\") or its table not found";
    TableModel m = table.getModel();
    int name = column(m, "Channel"), type = column(m, "Type"), num = column(m, "Num Msgs");
    int bad = column(m, "Undecodable");
    if (name < 0 || num < 0) return "lcm-spy's table has no 'Channel' or 'Num Msgs' column";
    for (int r = 0; r < m.getRowCount(); r++) {
      lines.add("channel " + m.getValueAt(r, name) + " messages " + m.getValueAt(r, num)
                + " undecodable " + (bad < 0 ? "?" : m.getValueAt(r, bad)) + " type "
                + (type < 0 ? "?" : m.getValueAt(r, type)));
    }
    return null;
  }
}
