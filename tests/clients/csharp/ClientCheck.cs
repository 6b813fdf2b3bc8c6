// ClientCheck.cs: a console program that exercises clients/csharp/VibsynthClient.cs for the Python tests
// (tests/clients/test_csharp_osc.py, tests/e2e/test_csharp_client.py). It reports what it observed as
// `key=value` lines on stdout; the Python side asserts on them. Usage: `mono ClientCheck.exe COMMAND ARGS...`.

using System;
using System.Collections.Generic;
using System.Diagnostics;
using System.Globalization;
using System.Text;
using System.Threading;
using System.Threading.Tasks;
using Vibsynth;

static class ClientCheck
{
    static readonly CultureInfo Inv = CheckMain.Inv;

    static int Main(string[] args)
    {
        return CheckMain.Run(args, new Dictionary<string, Action<string[]>>
        {
            { "encode", a => Encode() },
            { "decode", Decode },
            { "args", a => Arguments(CheckMain.Int(a[0])) },
            { "knobs", a => Knobs(CheckMain.Int(a[0])) },
            { "errors", a => Errors(CheckMain.Int(a[0])) },
            { "timeout", a => Timeout(CheckMain.Int(a[0])) },
            { "bundle", a => Bundles(CheckMain.Int(a[0])) },
            { "concurrent", a => Concurrent(CheckMain.Int(a[0])) },
            { "sources", a => Sources(CheckMain.Int(a[0])) },
            { "clips", a => Clips(CheckMain.Int(a[0]), a[1]) },
        });
    }

    static void Say(string key, object value) { CheckMain.Say(key, value); }

    static string Hex(byte[] data)
    {
        var text = new StringBuilder(data.Length * 2);
        foreach (byte b in data) text.Append(b.ToString("x2", Inv));
        return text.ToString();
    }

    static byte[] Unhex(string hex)
    {
        var data = new byte[hex.Length / 2];
        for (int i = 0; i < data.Length; i++) data[i] = byte.Parse(hex.Substring(2 * i, 2), NumberStyles.HexNumber, Inv);
        return data;
    }

    // ------------------------------------------------------------------ codec
    // The same packets are built by python-osc in the test; the bytes must be identical.
    static void Encode()
    {
        Say("empty", Hex(Osc.EncodeMessage("/vibsynth/panic")));
        Say("float", Hex(Osc.EncodeMessage("/vibsynth/ch/2/intensity", 0.5f)));
        Say("texture", Hex(Osc.EncodeMessage("/vibsynth/texture", 0.25f, -1.75f)));
        Say("int", Hex(Osc.EncodeMessage("/vibsynth/mute", 1)));
        Say("negative_int", Hex(Osc.EncodeMessage("/x", -123456789)));
        Say("string3", Hex(Osc.EncodeMessage("/vibsynth/preset", "abc")));
        Say("string4", Hex(Osc.EncodeMessage("/vibsynth/preset", "abcd")));
        Say("unicode", Hex(Osc.EncodeMessage("/vibsynth/preset", "velours-\u00e9t\u00e9-\u89e6")));
        Say("mixed", Hex(Osc.EncodeMessage("/vibsynth/ch/1/play", "impact", 0.8f, 1.5f, 3)));
        Say("double_long", Hex(Osc.EncodeMessage("/d", 3.141592653589793, 1L << 40)));
        Say("blob5", Hex(Osc.EncodeMessage("/b", new byte[] { 1, 2, 3, 4, 5 })));
        Say("blob0", Hex(Osc.EncodeMessage("/b", new byte[0])));
        Say("bools", Hex(Osc.EncodeMessage("/t", true, false)));
        Say("float_special", Hex(Osc.EncodeMessage("/f", 1e-38f, -0f, 3.4e38f)));
        var inner = new List<byte[]> { Osc.EncodeMessage("/vibsynth/ch/1/intensity", 0.5f), Osc.EncodeMessage("/vibsynth/ch/2/balance", 1f) };
        Say("bundle_now", Hex(Osc.EncodeBundle(OscTimeTag.Immediately, inner)));
        // 2024-03-01 12:00:00.25 UTC: a fraction python-osc's float arithmetic represents exactly
        var when = new DateTime(2024, 3, 1, 12, 0, 0, DateTimeKind.Utc).AddTicks(TimeSpan.TicksPerSecond / 4);
        Say("bundle_at", Hex(Osc.EncodeBundle(OscTimeTag.FromDateTime(when), inner)));
        Say("bundle_at_ntp", OscTimeTag.FromDateTime(when).Value);
        Say("bundle_at_roundtrip", OscTimeTag.FromDateTime(when).ToDateTime() == when);
        Say("nested", Hex(Osc.EncodeBundle(OscTimeTag.Immediately, new List<byte[]> { Osc.EncodeBundle(OscTimeTag.FromDateTime(when), inner) })));
        // the client's own commands, through a bundle (nothing is sent)
        using (var client = new VibsynthClient("127.0.0.1", 9))
        {
            VibsynthBundle b = client.At(when);
            b.SetTexture(2, 0.6f, -0.5f);
            b.SetIntensity(0.25f);
            b.Mute(3);
            b.SetGlide(150f);
            b.LoadPreset(1, "velvet");
            b.SourcePosition(4, 0.01f, -0.02f, 0.5f);
            b.SourceRolloff(4, Rolloff.InverseSquare);
            b.PlayClip(2, "heartbeat", 0.5f, 2f, 4);
            b.StopClip(2, 80f);
            b.Panic();
            Say("commands", Hex(b.Encode()));
            Say("commands_count", b.Count);
            Say("sent", client.Sent);
        }
        // now + delay: within a few ms of the system clock
        double ahead = (OscTimeTag.FromNow(0.5).ToDateTime() - DateTime.UtcNow).TotalSeconds;
        Say("from_now_0.5", ahead);
    }

    // One line per packet: "null", or its messages separated by " | ", each "TIMETAG ADDRESS_HEX TAGS ARG..."
    // with every value in an unambiguous form (numbers in decimal, float bits and text in hex).
    static void Decode(string[] args)
    {
        for (int i = 0; i < args.Length; i++)
        {
            List<OscReceived> messages = Osc.Decode(Unhex(args[i]));
            var parts = new List<string>();
            if (messages != null)
                foreach (OscReceived m in messages) parts.Add(Canonical(m));
            Say("packet" + (i + 1), messages == null ? "null" : string.Join(" | ", parts.ToArray()));
        }
    }

    static string Canonical(OscReceived received)
    {
        OscMessage m = received.Message;
        var fields = new List<string>();
        fields.Add(received.TimeTag.Value.ToString(Inv));
        fields.Add(Hex(Encoding.UTF8.GetBytes(m.Address)));
        fields.Add(m.TypeTags.Length == 0 ? "-" : m.TypeTags);
        for (int k = 0; k < m.Count; k++)
        {
            object v = m.Arguments[k];
            switch (m.TypeTags[k])
            {
                case 'f': fields.Add(Hex(Osc.EncodeMessage("/", (float)v)).Substring(16)); break;
                case 'd': fields.Add(BitConverter.DoubleToInt64Bits((double)v).ToString("x16", Inv)); break;
                case 's': case 'S': fields.Add(Hex(Encoding.UTF8.GetBytes((string)v)) + "."); break;
                case 'b': fields.Add(Hex((byte[])v) + "."); break;
                case 't': fields.Add(((OscTimeTag)v).Value.ToString(Inv)); break;
                case 'c': fields.Add(((int)(char)v).ToString(Inv)); break;
                case 'T': case 'F': case 'N': case 'I': fields.Add(m.TypeTags[k].ToString()); break;
                default: fields.Add(Convert.ToString(v, Inv)); break;
            }
        }
        return string.Join(" ", fields.ToArray());
    }

    // ------------------------------------------------------------------ argument checks (no server needed)
    static void Arguments(int port)
    {
        using (var client = new VibsynthClient("127.0.0.1", port))
        {
            var cases = new List<KeyValuePair<string, Action>>
            {
                Case("intensity_nan", () => client.SetIntensity(float.NaN)),
                Case("intensity_above", () => client.SetIntensity(1.5f)),
                Case("intensity_below", () => client.SetIntensity(1, -0.01f)),
                Case("balance_inf", () => client.SetBalance(float.PositiveInfinity)),
                Case("balance_beyond_any_config", () => client.SetBalance(2, 10.5f)),
                Case("texture_nan_balance", () => client.SetTexture(0.5f, float.NaN)),
                Case("channel_zero", () => client.SetTexture(0, 0.5f, 0f)),
                Case("channel_65", () => client.SetIntensity(65, 0.5f)),
                Case("glide_negative", () => client.SetGlide(-1f)),
                Case("glide_above", () => client.SetGlide(1, 10001f)),
                Case("speed_negative", () => client.SetSpeed(-3f)),
                Case("preset_empty", () => client.LoadPreset("")),
                Case("preset_null", () => client.LoadPreset(1, null)),
                Case("preset_nul", () => client.LoadPreset("a\0b")),
                Case("preset_long", () => client.LoadPreset(new string('x', 1025))),
                Case("source_zero", () => client.SourcePosition(0, 0f, 0f)),
                Case("source_17", () => client.SourceOn(17)),
                Case("source_pos_nan", () => client.SourcePosition(1, 0f, float.NaN, 0f)),
                Case("source_radius_zero", () => client.SourceRadius(1, 0f)),
                Case("source_intensity_above", () => client.SourceIntensity(1, 2f)),
                Case("set_source_nan", () => client.SetSource(1, 0f, 0f, float.NegativeInfinity, 0.5f, 0f)),
                Case("clip_channel_zero", () => client.PlayClip(0, "impact")),
                Case("clip_name_empty", () => client.PlayClip(1, "")),
                Case("clip_name_long", () => client.PlayClipAll(new string('c', 129))),
                Case("clip_gain_negative", () => client.PlayClip(1, "impact", -0.5f)),
                Case("clip_rate_zero", () => client.PlayClip(1, "impact", 1f, 0f)),
                Case("clip_rate_nan", () => client.PlayClipAll("impact", 1f, float.NaN)),
                Case("clip_loops_negative", () => client.PlayClip(1, "impact", 1f, 1f, -1)),
                Case("clip_loops_above", () => client.PlayClip(1, "impact", null, null, 10001)),
                Case("clip_gain_above", () => client.PlayClipAll("impact", 4.5f)),
                Case("clip_rate_above", () => client.PlayClip(2, "impact", 1f, 21f)),
                Case("stop_release_negative", () => client.StopClip(1, -5f)),
                Case("stop_all_release_nan", () => client.StopClipAll(float.NaN)),
                Case("bundle_time_negative", () => client.At(-1.0)),
                Case("bundle_time_nan", () => client.At(double.NaN)),
                Case("timeout_zero", () => client.Timeout = TimeSpan.Zero),
                Case("get_channel_zero", () => client.GetIntensity(0)),
                Case("get_source_17", () => client.GetSourceOn(17)),
                Case("address_no_slash", () => client.Send("vibsynth/intensity", 0.5f)),
                Case("unsupported_type", () => client.Send("/x", new object[] { new DateTime(2020, 1, 1) })),
                Case("packet_too_big", () => client.SendPacket(new byte[70000])),
            };
            foreach (KeyValuePair<string, Action> c in cases)
            {
                try
                {
                    c.Value();
                    Say("bad." + c.Key, "no exception");
                }
                catch (ArgumentException e)
                {
                    Say("bad." + c.Key, "ArgumentException: " + e.Message.Split('\n')[0]);
                }
                catch (Exception e)
                {
                    Say("bad." + c.Key, e.GetType().Name + ": " + e.Message);
                }
            }
            Say("sent_after_bad", client.Sent);
            // the same methods with good values send one packet each
            client.SetIntensity(1f);
            client.SetIntensity(64, 0f);
            client.SetBalance(-10f);
            client.SetTexture(3, 0.5f, 3.5f);
            client.SetGlide(10000f);
            client.SetSpeed(0f);
            client.LoadPreset("velvet");
            client.SourcePosition(16, -1f, 2f);
            client.SourceRadius(1, 0.05f);
            client.SetSource(2, 0f, 0f, 0f, 0.5f, 0f, 0.1f, Rolloff.Phantom, true);
            client.PlayClip(1, "impact");
            client.PlayClip(1, "impact", null, null, 0);
            client.PlayClip(64, "impact", 4f, 0.05f, 10000);
            client.StopClip(1);
            client.StopClipAll(0f);
            Say("sent_after_good", client.Sent);
        }
    }

    static KeyValuePair<string, Action> Case(string name, Action action)
    {
        return new KeyValuePair<string, Action>(name, action);
    }

    // ------------------------------------------------------------------ against a server
    static void Knobs(int port)
    {
        using (var client = new VibsynthClient("localhost", port))
        {
            client.Timeout = TimeSpan.FromSeconds(5);
            Say("ping_ms", client.Ping().TotalMilliseconds);
            VibsynthStatus status = client.Status();
            Say("status.channels", status.Channels);
            Say("status.version", status.Version);
            Say("status.pairs", status.Pairs.Count);
            Say("status.first_key", status.Pairs[0].Key);
            Say("status.ch2.intensity_present", status.ContainsKey("ch2.intensity"));

            client.SetGlide(0f);
            client.SetTexture(1, 0.625f, -1.5f);
            client.SetIntensity(2, 0.375f);
            client.SetBalance(2, 2.25f);
            client.Mute(3);
            client.SetGlide(2, 250f);
            client.Sync();
            Say("ch1.texture", client.GetTexture(1));
            Say("ch1.intensity", client.GetIntensity(1));
            Say("ch1.balance", client.GetBalance(1));
            Say("ch2.intensity", client.GetIntensity(2));
            Say("ch2.balance", client.GetBalance(2));
            Say("ch2.glide", client.GetGlide(2));
            Say("ch3.mute", client.GetMute(3));
            Say("ch1.mute", client.GetMute(1));
            Say("ch1.preset", client.GetPreset(1) ?? "none");
            client.LoadPreset(3, "velvet");
            client.Sync();
            Say("ch3.preset", client.GetPreset(3));
            Say("ch3.generic", client.Get(3, "intensity"));
            // async from a thread without a synchronization context, awaited together
            Task<float> a = client.GetIntensityAsync(1);
            Task<Texture> b = client.GetTextureAsync(2);
            Task<bool> c = client.GetMuteAsync(3);
            Task.WaitAll(a, b, c);
            Say("async.ch1.intensity", a.Result);
            Say("async.ch2.texture", b.Result);
            Say("async.ch3.mute", c.Result);
            Say("sent", client.Sent);
            Say("malformed", client.Malformed);
        }
    }

    static void Errors(int port)
    {
        using (var client = new VibsynthClient("127.0.0.1", port))
        {
            client.Timeout = TimeSpan.FromSeconds(5);
            client.SetGlide(1, 0f);
            client.SetTexture(1, 0.25f, -1.5f);
            client.Sync();
            var seen = new List<string>();
            client.ErrorReceived += (sender, e) => { lock (seen) seen.Add(e.Error.Address); };
            // a query the server refuses: the error reply fails that query
            Report("get_channel_9", () => client.GetIntensity(9));
            Report("get_unknown_setting", () => client.Get(1, "colour"));
            Report("get_async_channel_9", () => client.GetBalanceAsync(9).Wait());
            // setters the server refuses (within what the client may check): Sync reports them all
            client.SetBalance(1, 5f);              // beyond this server's live range (-3.5..3.5)
            client.SetIntensity(9, 0.5f);          // this server has 3 channels
            client.LoadPreset("no-such-preset");
            client.SetIntensity(1, 0.5f);          // fine
            Report("sync", () => client.Sync());
            Say("after_sync.errors", client.TakeErrors().Count);
            Say("events", string.Join(",", seen.ToArray()));
            client.Sync(); // nothing refused since: no exception
            Say("sync_clean", "ok");
            Say("ch1.intensity", client.GetIntensity(1));
            Say("ch1.balance", client.GetBalance(1));
        }
    }

    static void Report(string key, Action action) { CheckMain.Report(key, action); }

    static void Timeout(int closedPort)
    {
        using (var client = new VibsynthClient("127.0.0.1", closedPort))
        {
            client.Timeout = TimeSpan.FromMilliseconds(300);
            var watch = Stopwatch.StartNew();
            Report("get", () => client.GetIntensity(1));
            Say("get.elapsed_ms", watch.Elapsed.TotalMilliseconds);
            watch.Restart();
            Report("status", () => client.Status(TimeSpan.FromMilliseconds(150)));
            Say("status.elapsed_ms", watch.Elapsed.TotalMilliseconds);
            watch.Restart();
            Task<float> pending = client.GetBalanceAsync(2, TimeSpan.FromMilliseconds(200));
            Say("async.completed_on_return", pending.IsCompleted); // false: the call did not wait
            Report("async", () => pending.Wait());
            Say("async.elapsed_ms", watch.Elapsed.TotalMilliseconds);
            try
            {
                throw pending.Exception.InnerException;
            }
            catch (VibsynthTimeoutException e)
            {
                Say("async.request", e.Request);
                Say("async.port", e.Port);
            }
            // a query waiting when the client is disposed ends at once
            Task<bool> waiting = client.GetMuteAsync(1, TimeSpan.FromSeconds(30));
            watch.Restart();
            client.Dispose();
            Report("disposed", () => waiting.Wait());
            Say("disposed.elapsed_ms", watch.Elapsed.TotalMilliseconds);
            Report("after_dispose", () => client.SetIntensity(0.5f));
        }
    }

    static void Bundles(int port)
    {
        using (var client = new VibsynthClient("127.0.0.1", port))
        {
            client.Timeout = TimeSpan.FromSeconds(5);
            client.SetGlide(0f);
            client.SetTexture(0.25f, 0f);
            client.Sync();
            VibsynthStatus before = client.Status();
            // an immediate bundle: applied together
            VibsynthBundle now = client.Bundle();
            now.SetIntensity(1, 0.5f);
            now.SetIntensity(2, 0.75f);
            now.Send();
            client.Sync();
            Say("now.ch1", client.GetIntensity(1));
            Say("now.ch2", client.GetIntensity(2));
            // a timetagged bundle 0.6 s ahead: scheduled by the server, not applied yet
            VibsynthBundle later = client.At(0.6);
            later.SetTexture(3, 0.875f, 1.25f);
            later.Send();
            client.Sync();
            VibsynthStatus queued = client.Status();
            Say("scheduled_delta", queued.GetNumber("scheduled") - before.GetNumber("scheduled"));
            Say("scheduled_pending", queued.GetNumber("scheduled_pending"));
            Say("later.ch3", client.GetTexture(3));
            Thread.Sleep(900);
            Say("after.scheduled_pending", client.Status().GetNumber("scheduled_pending"));
            // beyond the server's horizon (10 s): refused with an error about the message
            VibsynthBundle far = client.At(20.0);
            far.SetIntensity(1, 0.1f);
            far.Send();
            Report("far", () => client.Sync());
            Say("far.ch1", client.GetIntensity(1));
            // a bundle can be sent once
            Report("twice", () => now.Send());
        }
    }

    static void Concurrent(int port)
    {
        using (var client = new VibsynthClient("127.0.0.1", port))
        {
            client.Timeout = TimeSpan.FromSeconds(10);
            client.SetGlide(0f);
            client.Unmute();
            const int threads = 8, rounds = 60;
            int wrong = 0, done = 0;
            var errors = new List<string>();
            var workers = new List<Thread>();
            for (int t = 0; t < threads; t++)
            {
                int channel = t % 3 + 1;
                int seed = t;
                var worker = new Thread(() =>
                {
                    try
                    {
                        for (int r = 0; r < rounds; r++)
                        {
                            if (channel == seed + 1) // the first thread of each channel writes it, the others read
                            {
                                float value = ((r * 7 + seed) % 100) / 100f;
                                client.SetIntensity(channel, value);
                                float back = client.GetIntensity(channel);
                                if (back != value) Interlocked.Increment(ref wrong);
                            }
                            else
                            {
                                Texture texture = client.GetTexture(channel);
                                if (texture.Intensity < 0f || texture.Intensity > 1f) Interlocked.Increment(ref wrong);
                                if (client.GetMute(channel)) Interlocked.Increment(ref wrong);
                            }
                            Interlocked.Increment(ref done);
                        }
                    }
                    catch (Exception e)
                    {
                        lock (errors) errors.Add(e.GetType().Name + ": " + e.Message);
                    }
                });
                workers.Add(worker);
                worker.Start();
            }
            foreach (Thread worker in workers) worker.Join();
            Say("threads.done", done);
            Say("threads.wrong", wrong);
            Say("threads.errors", errors.Count == 0 ? "none" : errors[0]);
            // many async queries in flight at once, on distinct channels and settings
            client.SetTexture(1, 0.125f, -2f);
            client.SetTexture(2, 0.5f, 0.5f);
            client.SetTexture(3, 1f, 3f);
            var tasks = new List<Task<Texture>>();
            for (int i = 0; i < 300; i++) tasks.Add(client.GetTextureAsync(i % 3 + 1));
            Task.WaitAll(tasks.ToArray());
            int mismatched = 0;
            for (int i = 0; i < tasks.Count; i++)
            {
                Texture t = tasks[i].Result;
                float want = i % 3 == 0 ? 0.125f : i % 3 == 1 ? 0.5f : 1f;
                if (t.Intensity != want) mismatched++;
            }
            Say("async.count", tasks.Count);
            Say("async.mismatched", mismatched);
            Say("ignored", client.Ignored);
        }
    }

    // ------------------------------------------------------------------ spatial sources and clips
    // On a server with the glove layout (6 channels: thumb, index, middle, ring, little, palm).
    static void Sources(int port)
    {
        using (var client = new VibsynthClient("127.0.0.1", port))
        {
            client.Timeout = TimeSpan.FromSeconds(5);
            // source 1 on the index fingertip (-0.035, 0.110, 0), everything in one bundle
            client.SetSource(1, -0.035f, 0.110f, 0f, 0.75f, 1.5f, 0.03f, Rolloff.Smooth, true);
            // source 2 built message by message
            client.SourcePosition(2, 0.03f, 0.04f, 0.005f);
            client.SourceTexture(2, 0.5f, -1f);
            client.SourceRadius(2, 0.12f);
            client.SourceRolloff(2, Rolloff.Phantom);
            client.SourceSpeed(2, true);
            client.SourceOn(2, true);
            client.Sync();
            Say("s1.pos", Position(client.GetSourcePosition(1)));
            Say("s1.texture", client.GetSourceTexture(1));
            Say("s1.radius", client.GetSourceRadius(1));
            Say("s1.rolloff", client.GetSourceRolloff(1));
            Say("s1.on", client.GetSourceOn(1));
            Say("s1.speed", client.GetSourceSpeed(1));
            Say("s2.pos", Position(client.GetSourcePosition(2)));
            Say("s2.texture", client.GetSourceTexture(2));
            Say("s2.radius", client.GetSourceRadius(2));
            Say("s2.rolloff", client.GetSourceRolloff(2));
            Say("s2.on", client.GetSourceOn(2));
            Say("s2.speed", client.GetSourceSpeed(2));
            client.SourceIntensity(2, 0.25f);
            client.SourceBalance(2, 0.5f);
            client.SourcePosition(2, 0.01f, -0.02f);
            client.Sync();
            Say("s2.texture2", client.GetSourceTexture(2));
            Say("s2.pos2", Position(client.GetSourcePosition(2)));
            client.SourcePreset(2, "velvet");
            client.Sync();
            Say("s2.preset", client.GetSourcePreset(2));
            Say("s1.preset", client.GetSourcePreset(1) ?? "none");
            client.SourceOn(2, false);
            client.SourceSpeed(2, false);
            client.Sync();
            Say("s2.off", client.GetSourceOn(2));
            Say("s1.generic", client.GetSource(1, "intensity"));
            // a timetagged source move: scheduled, applied later. 2 s ahead, so the query right
            // after it comes before it even on a loaded machine; then polled (up to 10 s) until it
            // applies: the stream's clock, not this client's sleep, decides when.
            VibsynthBundle later = client.At(2.0);
            later.SourcePosition(1, -0.005f, 0.120f, 0f); // the middle fingertip
            later.Send();
            client.Sync();
            Say("s1.pos_scheduled", Position(client.GetSourcePosition(1)));
            string moved = Position(client.GetSourcePosition(1));
            for (int k = 0; k < 200 && moved != "-0.005,0.12,0"; k++)
            {
                Thread.Sleep(50);
                moved = Position(client.GetSourcePosition(1));
            }
            Say("s1.pos_after", moved);
            client.SourcePosition(1, -0.035f, 0.110f, 0f); // back to the index for the Python side
            client.Sync();
            // refusals
            Report("bad_setting", () => client.GetSource(1, "colour"));
            client.SourcePreset(1, "no-such-preset");
            client.SourceBalance(1, 5f); // beyond the live range
            Report("bad_values", () => client.Sync());
            Say("s1.texture_after_refusals", client.GetSourceTexture(1));
        }
    }

    static string Position(float[] p)
    {
        return string.Format(Inv, "{0:R},{1:R},{2:R}", p[0], p[1], p[2]);
    }

    // On a server with 3 channels and the clip player; `clip` is a shipped clip's name.
    static void Clips(int port, string clip)
    {
        using (var client = new VibsynthClient("127.0.0.1", port))
        {
            client.Timeout = TimeSpan.FromSeconds(5);
            client.SetGlide(0f);
            client.SetTexture(0.2f, 0f);
            client.Sync();
            Say("idle", client.GetClip(1));
            client.PlayClip(1, clip, 1f, 1f, 0); // looping until stopped
            client.PlayClip(2, clip, 0.5f, 2f, 3);
            client.Sync();
            Thread.Sleep(150);
            ClipState one = client.GetClip(1);
            Say("ch1.name", one.Name);
            Say("ch1.playing", one.IsPlaying);
            Say("ch1.position_ms", one.PositionMs);
            Say("ch1.loops_left", one.LoopsLeft);
            ClipState two = client.GetClip(2);
            Say("ch2.name", two.Name);
            Say("ch2.loops_left", two.LoopsLeft);
            Say("ch3", client.GetClip(3));
            Say("ch1.driver", client.GetDriver(1));
            Say("ch3.driver", client.GetDriver(3));
            VibsynthStatus status = client.Status();
            Say("status.clips_playing", status.GetNumber("clips_playing"));
            Say("status.ch1.clip", status.GetString("ch1.clip"));
            client.StopClip(1, 20f);
            client.StopClip(2);
            client.Sync();
            Thread.Sleep(200);
            Say("stopped", client.GetClip(1));
            Say("stopped.driver", client.GetDriver(1));
            Say("stopped.texture", client.GetTexture(1));
            // every channel, started by a timetagged bundle 0.3 s ahead, then stopped for all
            VibsynthBundle later = client.At(0.3);
            later.PlayClipAll(clip, 0.8f, 1f, 0);
            later.Send();
            client.Sync();
            Say("all.before", client.GetClip(3));
            Thread.Sleep(600);
            Say("all.after", client.GetClip(3).Name);
            client.StopClipAll(0f);
            client.Sync();
            Thread.Sleep(200);
            Say("all.stopped", client.GetClip(3));
            // refusals
            client.PlayClip(1, "no-such-clip");
            client.PlayClip(9, clip);
            Report("refused", () => client.Sync());
            Say("refused.ch1", client.GetClip(1));
        }
    }
}
