// FollowCheck.cs: the C# client's live Follow methods against a real `vibsynth serve --follow FILE.wav`
// (tests/clients/test_csharp_follow.py). Reports `key=value` lines (CheckMain.Say); the Python side asserts
// on them and reads the server's state with the Python client. Usage: `mono FollowCheck.exe follow PORT`.

using System;
using System.Collections.Generic;
using Vibsynth;

static class FollowCheck
{
    static int Main(string[] args)
    {
        return CheckMain.Run(args, new Dictionary<string, Action<string[]>>
        {
            { "follow", a => Follow(CheckMain.Int(a[0])) },
        });
    }

    static void Say(string key, object value) { CheckMain.Say(key, value); }

    static void Report(string key, Action action) { CheckMain.Report(key, action); }

    // A server with 2 channels that follows a mono file in audio mode (both channels follow it).
    static void Follow(int port)
    {
        using (var client = new VibsynthClient("127.0.0.1", port))
        {
            client.Timeout = TimeSpan.FromSeconds(5);
            Say("default.range", client.GetFollowRange());
            Say("default.focus", client.GetFollowFocus());
            client.SetFollowGain(4.5f);
            client.SetFollowGate(-45f);
            client.SetFollowRange(30f);
            client.SetFollowFocus("effects");
            client.Sync();
            Say("gain", client.GetFollowGain());
            Say("gate", client.GetFollowGate());
            Say("range", client.GetFollowRange());
            Say("focus", client.GetFollowFocus());
            Say("async.range", client.GetFollowRangeAsync().Result);
            // one channel back to its knobs, then every channel following again
            client.SetFollow(2, false);
            client.Sync();
            Say("ch1.follow", client.GetFollow(1));
            Say("ch2.follow", client.GetFollow(2));
            Say("ch1.driver", client.GetDriver(1));
            Say("ch2.driver", client.GetDriver(2));
            client.SetFollow(false);
            client.Sync();
            Say("all_off.ch1", client.GetFollow(1));
            client.SetFollow(true);
            client.Sync();
            Say("all_on.ch2", client.GetFollowAsync(2).Result);
            // refusals: the server's ranges and names; nothing changes
            client.SetFollowRange(200f);
            client.SetFollowGain(-61f);
            client.SetFollowFocus("loud");
            client.SetFollow(9, true);
            Report("refused", () => client.Sync());
            Say("refused.gain", client.GetFollowGain());
            Say("refused.range", client.GetFollowRange());
            Say("refused.focus", client.GetFollowFocus());
            // what no server takes is refused here, and nothing is sent
            long sent = client.Sent;
            Report("bad.gain_nan", () => client.SetFollowGain(float.NaN));
            Report("bad.range_inf", () => client.SetFollowRange(float.PositiveInfinity));
            Report("bad.focus_null", () => client.SetFollowFocus(null));
            Report("bad.focus_empty", () => client.SetFollowFocus(""));
            Report("bad.channel_zero", () => client.SetFollow(0, true));
            Say("bad.sent", client.Sent - sent);
            // a bundle carries them too (applied together)
            VibsynthBundle both = client.Bundle();
            both.SetFollowGain(-3f);
            both.SetFollowRange(48f);
            both.Send();
            client.Sync();
            Say("bundle.gain", client.GetFollowGain());
            Say("bundle.range", client.GetFollowRange());
        }
    }
}
