// SPDX-License-Identifier: MIT
// Java side of the LCM type round trip (the classes lcm-spy loads from the types jar): decode the
// bytes the C test encoded, check field values, re-encode and require identical bytes.
import java.io.ByteArrayOutputStream;
import java.io.DataOutputStream;
import java.nio.file.Files;
import java.nio.file.Path;
import java.util.Arrays;

public final class MsgsRoundTrip {
    private static int failures = 0;

    private static byte[] golden(String dir, String name) throws Exception {
        return Files.readAllBytes(Path.of(dir, name + ".bin"));
    }

    private static byte[] encode(lcm.lcm.LCMEncodable m) throws Exception {
        ByteArrayOutputStream bytes = new ByteArrayOutputStream();
        m.encode(new DataOutputStream(bytes));
        return bytes.toByteArray();
    }

    private static void check(boolean ok, String what) {
        System.out.println((ok ? "ok   " : "FAIL ") + what);
        if (!ok) {
            failures++;
        }
    }

    public static void main(String[] args) throws Exception {
        String dir = args[0];
        byte[] d;

        d = golden(dir, "b21r_experience_t");
        b21r.experience_t e = new b21r.experience_t(d);
        check(Arrays.equals(encode(e), d), "experience_t re-encodes identically");
        check(e.seq == 42 && e.run_id == 7 && e.reward == 10.0 && e.terminal, "experience_t fields");

        d = golden(dir, "b21r_teleop_t");
        b21r.teleop_t t = new b21r.teleop_t(d);
        check(Arrays.equals(encode(t), d), "teleop_t re-encodes identically");
        check(t.deadman && t.rotation_radps == 0.3 && t.mac[0] == (byte) 0xC0, "teleop_t fields");

        d = golden(dir, "b21r_command_t");
        b21r.command_t c = new b21r.command_t(d);
        check(Arrays.equals(encode(c), d) && c.command == b21r.command_t.CONFIRM_START_POSE, "command_t");

        d = golden(dir, "b21r_session_t");
        b21r.session_t se = new b21r.session_t(d);
        check(Arrays.equals(encode(se), d) && se.started_us == 1700000000000000L && se.nonce[0] == 0x42, "session_t");

        d = golden(dir, "b21r_pose_t");
        b21r.pose_t p = new b21r.pose_t(d);
        check(Arrays.equals(encode(p), d) && p.y_m == -2.25, "pose_t");

        d = golden(dir, "b21r_eval_t");
        b21r.eval_t v = new b21r.eval_t(d);
        check(Arrays.equals(encode(v), d) && v.steps[15] == 115 && v.successes == 8, "eval_t");

        d = golden(dir, "b21r_status_t");
        b21r.status_t s = new b21r.status_t(d);
        check(Arrays.equals(encode(s), d) && s.stop_detail.equals("laser silent for 0.35 s"), "status_t");

        d = golden(dir, "b21r_scan_t");
        b21r.scan_t sc = new b21r.scan_t(d);
        check(Arrays.equals(encode(sc), d) && sc.n_beams == 181, "scan_t");

        try {
            byte[] broken = golden(dir, "b21r_pose_t");
            broken[0] ^= 0x55;  // fingerprint
            new b21r.pose_t(broken);
            check(false, "corrupt fingerprint refused");
        } catch (java.io.IOException expected) {
            check(true, "corrupt fingerprint refused");
        }

        System.out.println(failures == 0 ? "all Java round trips passed" : failures + " failed");
        System.exit(failures == 0 ? 0 : 1);
    }
}
