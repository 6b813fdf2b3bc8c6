// UnityCheck.cs: drives clients/csharp/Unity/VibsynthContactSource.cs through the UnityEngine shim, as
// Unity would call it (OnEnable, collision messages, OnDisable), and reports `key=value` lines.
//   listen: the component sends to a UDP socket of this program, which reports every message it got.
//   server PORT: the component drives a real `vibsynth serve`; a client reads the source back.

using System;
using System.Collections.Generic;
using System.Globalization;
using System.Net;
using System.Net.Sockets;
using System.Reflection;
using System.Threading;
using UnityEngine;
using Vibsynth;

static class UnityCheck
{
    static readonly CultureInfo Inv = CheckMain.Inv;

    static int Main(string[] args)
    {
        return CheckMain.Run(args, new Dictionary<string, Action<string[]>>
        {
            { "listen", a => Listen() },
            { "server", a => Server(CheckMain.Int(a[0])) },
        });
    }

    static void Say(string key, object value) { CheckMain.Say(key, value); }

    // Unity calls these private messages by name; so does this program.
    static void Call(VibsynthContactSource component, string message, params object[] args)
    {
        MethodInfo method = typeof(VibsynthContactSource).GetMethod(message, BindingFlags.Instance | BindingFlags.NonPublic | BindingFlags.Public);
        if (method == null) throw new MissingMethodException("VibsynthContactSource has no " + message);
        method.Invoke(component, args);
    }

    static VibsynthContactSource Make(int port)
    {
        var component = new VibsynthContactSource();
        component.host = "127.0.0.1";
        component.port = port;
        component.source = 3;
        component.intensity = 0.7f;
        component.balance = -1f;
        component.radius = 0.04f;
        component.rolloff = Rolloff.Phantom;
        component.maxRateHz = 100f;
        component.intensityFromSpeed = false;
        var frame = new Transform();
        frame.position = new Vector3(1f, 0f, 2f); // the layout's origin in the world
        component.layoutFrame = frame;
        return component;
    }

    // The touch: a finger lands at (+10 mm, 0, +20 mm) in the layout, slides 30 mm along x in 0.1 s,
    // a second collider touches and leaves, then the finger leaves.
    static void Touch(VibsynthContactSource c)
    {
        Time.time = 10f;
        Call(c, "OnCollisionEnter", new Collision(new Vector3(1.005f, 0f, 2.02f), new Vector3(1.015f, 0f, 2.02f)));
        Say("touching.enter", c.Touching);
        for (int step = 1; step <= 10; step++)
        {
            Time.time = 10f + step * 0.005f; // physics at 200 Hz: the component sends at most 100 Hz
            Call(c, "OnCollisionStay", new Collision(new Vector3(1.01f + 0.0015f * step, 0f, 2.02f)));
        }
        Say("speed_mps", c.Speed.ToString("R", Inv));
        Say("position", c.Position.x.ToString("R", Inv) + "," + c.Position.y.ToString("R", Inv) + "," + c.Position.z.ToString("R", Inv));
        Call(c, "OnCollisionEnter", new Collision(new Vector3(1.05f, 0f, 2.05f)));
        Call(c, "OnCollisionExit", new Collision());
        Say("touching.after_one_exit", c.Touching);
        Call(c, "OnCollisionExit", new Collision());
        Say("touching.after_both", c.Touching);
        Say("speed_after", c.Speed.ToString("R", Inv));
    }

    static void Listen()
    {
        using (var socket = new Socket(AddressFamily.InterNetwork, SocketType.Dgram, ProtocolType.Udp))
        {
            socket.Bind(new IPEndPoint(IPAddress.Loopback, 0));
            VibsynthContactSource c = Make(((IPEndPoint)socket.LocalEndPoint).Port);
            Call(c, "OnEnable");
            Touch(c);
            Call(c, "OnDisable");
            Say("client_after_disable", c.Client == null ? "null" : "open");
            var buffer = new byte[65536];
            int n = 0;
            socket.ReceiveTimeout = 1000;
            while (true)
            {
                int count;
                try
                {
                    count = socket.Receive(buffer);
                }
                catch (SocketException)
                {
                    break;
                }
                var copy = new byte[count];
                Buffer.BlockCopy(buffer, 0, copy, 0, count);
                List<OscReceived> messages = Osc.Decode(copy);
                var parts = new List<string>();
                foreach (OscReceived m in messages) parts.Add(m.Message.ToString());
                Say("packet" + n++, string.Join(" | ", parts.ToArray()));
            }
            Say("packets", n);
            Say("warnings", UnityEngine.Debug.Warnings);
        }
    }

    static void Server(int port)
    {
        VibsynthContactSource c = Make(port);
        Call(c, "OnEnable");
        using (var reader = new VibsynthClient("127.0.0.1", port))
        {
            reader.Timeout = TimeSpan.FromSeconds(5);
            Time.time = 20f;
            Call(c, "OnCollisionEnter", new Collision(new Vector3(1.01f, 0f, 2.02f)));
            reader.Sync();
            float[] p = reader.GetSourcePosition(3);
            Say("pos", string.Format(Inv, "{0:R},{1:R},{2:R}", p[0], p[1], p[2]));
            Say("on", reader.GetSourceOn(3));
            Say("texture", reader.GetSourceTexture(3));
            Say("radius", reader.GetSourceRadius(3));
            Say("rolloff", reader.GetSourceRolloff(3));
            Say("speed_mode", reader.GetSourceSpeed(3));
            Time.time = 20.05f;
            Call(c, "OnCollisionStay", new Collision(new Vector3(1.03f, 0f, 2.01f)));
            reader.Sync();
            p = reader.GetSourcePosition(3);
            Say("pos2", string.Format(Inv, "{0:R},{1:R},{2:R}", p[0], p[1], p[2]));
            Call(c, "OnCollisionExit", new Collision());
            reader.Sync();
            Say("on_after_exit", reader.GetSourceOn(3));
            Call(c, "OnDisable");
            Say("warnings", UnityEngine.Debug.Warnings);
        }
    }
}
