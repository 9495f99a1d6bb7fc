// SPDX-License-Identifier: MIT
// B21rSpyProbe: a Java agent for the lcm-spy tests. Loaded into lcm-spy's JVM with
// JDK_JAVA_OPTIONS=-javaagent:b21r-spy-probe.jar=OUT (lcm-spy's launcher fixes the class path, so an
// agent is the one way in), it reads every showing window through the Java accessibility API
// (javax.accessibility: the tree an assistive technology sees) and writes what it finds to OUT
// every 500 ms, replaced atomically: a "window" line per window (title, screen bounds) and, for
// every table in it, a "table" line (screen bounds), a "header" line and one "row" line per row,
// cells separated by tabs. The test reads the channel table from it: channel names, the type
// lcm-spy decoded ("status_t", or "?? <fingerprint>" for an unknown type), message counts.
import java.awt.EventQueue;
import java.awt.Point;
import java.awt.Window;
import java.io.IOException;
import java.nio.charset.StandardCharsets;
import java.nio.file.Files;
import java.nio.file.Path;
import java.nio.file.Paths;
import java.nio.file.StandardCopyOption;
import javax.accessibility.Accessible;
import javax.accessibility.AccessibleComponent;
import javax.accessibility.AccessibleContext;
import javax.accessibility.AccessibleTable;

public final class B21rSpyProbe {
  private B21rSpyProbe() {}

  public static void premain(String args) {
    final Path out = Paths.get(args == null || args.isEmpty() ? "b21r-spy-probe.txt" : args);
    Thread t = new Thread(() -> {
      while (true) {
        try {
          Thread.sleep(500);
          final StringBuilder sb = new StringBuilder();
          // Swing's components are read on the event dispatch thread only.
          EventQueue.invokeAndWait(() -> dumpWindows(sb));
          Path tmp = out.resolveSibling(out.getFileName() + ".tmp");
          Files.write(tmp, sb.toString().getBytes(StandardCharsets.UTF_8));
          Files.move(tmp, out, StandardCopyOption.REPLACE_EXISTING, StandardCopyOption.ATOMIC_MOVE);
        } catch (InterruptedException e) {
          return;
        } catch (IOException | java.lang.reflect.InvocationTargetException | RuntimeException e) {
          // A window closing mid-walk, a full disk: try again next period.
        }
      }
    }, "b21r-spy-probe");
    t.setDaemon(true);
    t.start();
  }

  private static String bounds(AccessibleContext ac) {
    AccessibleComponent c = ac.getAccessibleComponent();
    if (c == null || !c.isShowing()) {
      return "hidden";
    }
    Point p = c.getLocationOnScreen();
    java.awt.Dimension d = c.getSize();
    return p == null || d == null ? "hidden" : p.x + " " + p.y + " " + d.width + " " + d.height;
  }

  private static String name(Accessible a) {
    if (a == null || a.getAccessibleContext() == null) {
      return "";
    }
    String n = a.getAccessibleContext().getAccessibleName();
    return n == null ? "" : n.replace('\t', ' ').replace('\n', ' ');
  }

  private static void dumpWindows(StringBuilder sb) {
    for (Window w : Window.getWindows()) {
      if (!w.isShowing() || w.getAccessibleContext() == null) {
        continue;
      }
      AccessibleContext ac = w.getAccessibleContext();
      sb.append("window\t").append(ac.getAccessibleName()).append('\t').append(bounds(ac)).append('\n');
      walk(ac, sb, 0);
    }
  }

  private static void walk(AccessibleContext ac, StringBuilder sb, int depth) {
    if (depth > 64) {
      return;
    }
    AccessibleTable table = ac.getAccessibleTable();
    if (table != null) {
      sb.append("table\t").append(bounds(ac)).append('\n');
      AccessibleTable header = table.getAccessibleColumnHeader();
      sb.append("header");
      for (int c = 0; c < table.getAccessibleColumnCount(); ++c) {
        String h = header != null && header.getAccessibleRowCount() > 0 ? name(header.getAccessibleAt(0, c)) : "";
        if (h.isEmpty() && table.getAccessibleColumnDescription(c) != null) {
          h = name(table.getAccessibleColumnDescription(c));
        }
        sb.append('\t').append(h);
      }
      sb.append('\n');
      for (int r = 0; r < table.getAccessibleRowCount(); ++r) {
        sb.append("row");
        for (int c = 0; c < table.getAccessibleColumnCount(); ++c) {
          sb.append('\t').append(name(table.getAccessibleAt(r, c)));
        }
        sb.append('\n');
      }
      return;
    }
    for (int i = 0; i < ac.getAccessibleChildrenCount(); ++i) {
      Accessible child = ac.getAccessibleChild(i);
      if (child != null && child.getAccessibleContext() != null) {
        walk(child.getAccessibleContext(), sb, depth + 1);
      }
    }
  }
}
