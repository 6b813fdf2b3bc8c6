// Generated from clients/csharp/Unity/VibsynthContactSource.cs by scripts/sync_unity.py: edit there, then run the script.

// VibsynthContactSource.cs: a Unity component that turns this object's collision contacts into a
// vibsynth touch source. Where it touches, expressed in the actuator layout's frame, is the source's
// position; the source is on while something touches and off when the last contact ends. The server
// mixes the source onto the actuators near that point (its layout, radius and roll-off law), and with
// Intensity From Speed derives the source's intensity from how fast the point moves (its speed curve).
//
// Needs VibsynthClient.cs in the project. Put it on a GameObject with a Collider and a Rigidbody (or
// touched by one), e.g. a fingertip or a tool; set Layout Frame to the Transform whose origin and axes
// are the layout's (x, y, z) in metres: the glove's hand bone, the vest's back, the wristband.
//
// Threading: Unity calls the collision messages on the main thread; each sends one UDP datagram and
// never waits for the server. Server refusals (e.g. a source number the server does not have) are
// logged from the client's receive thread, at most once a second.

using System;
using System.Threading;
using UnityEngine;
using Vibsynth;

[AddComponentMenu("Vibsynth/Contact Source")]
[DisallowMultipleComponent]
public sealed class VibsynthContactSource : MonoBehaviour
{
    [Header("Server")]
    [Tooltip("Host name or IP address of the machine running `vibsynth serve`")]
    public string host = "127.0.0.1";

    [Tooltip("The server's UDP port (osc.port)")]
    public int port = VibsynthClient.DefaultPort;

    [Tooltip("The server's address prefix (osc.prefix)")]
    public string prefix = VibsynthClient.DefaultPrefix;

    [Header("Source")]
    [Tooltip("The spatial source this object's contacts drive (1..16); give each touching object its own")]
    [Range(1, VibsynthCommands.MaxSources)]
    public int source = 1;

    [Tooltip("The actuator layout's frame: its origin and axes are the layout's x, y, z (metres, scale 1). " +
             "Empty: world coordinates")]
    public Transform layoutFrame;

    [Tooltip("The source's intensity while touching, 0..1 (not used with Intensity From Speed)")]
    [Range(0f, 1f)]
    public float intensity = 0.8f;

    [Tooltip("The source's balance (knob units; brighter when positive)")]
    [Range(-3.5f, 3.5f)]
    public float balance = 0f;

    [Tooltip("How far from the contact the source reaches, in metres")]
    [Range(0.001f, 0.5f)]
    public float radius = 0.03f;

    [Tooltip("How the source fades with distance to an actuator")]
    public Rolloff rolloff = Rolloff.Smooth;

    [Tooltip("The server derives the intensity from how fast the contact slides (its speed curve): " +
             "a sliding finger feels the texture, a resting one does not")]
    public bool intensityFromSpeed = true;

    [Tooltip("Position messages per second at most while touching (physics may run faster)")]
    [Range(10f, 500f)]
    public float maxRateHz = 120f;

    VibsynthClient client;
    int contacts;
    float lastSentTime = float.NegativeInfinity;
    Vector3 lastPoint;
    float lastPointTime;
    bool hasPoint;
    long lastLogTicks;
    int suppressedLogs;

    /// <summary>Is anything touching this object now?</summary>
    public bool Touching { get { return contacts > 0; } }

    /// <summary>The last contact point sent, in the layout's frame (metres).</summary>
    public Vector3 Position { get; private set; }

    /// <summary>How fast the contact point slides over the layout, in m/s (0 when not touching).</summary>
    public float Speed { get; private set; }

    /// <summary>The client this component sends with (null while disabled); usable for other commands too.</summary>
    public VibsynthClient Client { get { return client; } }

    void OnEnable()
    {
        try
        {
            client = new VibsynthClient(host, port, prefix);
        }
        catch (Exception e)
        {
            Debug.LogError("VibsynthContactSource: cannot reach " + host + ":" + port + ": " + e.Message);
            enabled = false;
            return;
        }
        client.ErrorReceived += OnServerError;
    }

    void OnDisable()
    {
        if (client == null) return;
        if (contacts > 0) Send(() => client.SourceOn(source, false));
        client.Dispose();
        client = null;
        contacts = 0;
        hasPoint = false;
        Speed = 0f;
    }

    void OnValidate()
    {
        port = Mathf.Clamp(port, 1, 65535);
        source = Mathf.Clamp(source, 1, VibsynthCommands.MaxSources);
        radius = Mathf.Clamp(radius, 0.001f, VibsynthCommands.PositionLimit);
    }

    void OnCollisionEnter(Collision collision)
    {
        bool first = contacts == 0;
        contacts++;
        Vector3 point;
        if (client == null || !ContactInLayout(collision, out point)) return;
        Track(point, Time.time);
        if (first) // everything at once, applied together: how it is felt, where, on
            Send(() =>
            {
                VibsynthBundle touch = client.Bundle();
                touch.SourceSpeed(source, intensityFromSpeed);
                touch.SetSource(source, point.x, point.y, point.z, intensity, balance, radius, rolloff, true);
                touch.Send();
            });
        else // another collider while touching: the source moves to the newest contact
            Send(() => client.SourcePosition(source, point.x, point.y, point.z));
        lastSentTime = Time.time;
    }

    void OnCollisionStay(Collision collision)
    {
        Vector3 point;
        if (client == null || !ContactInLayout(collision, out point)) return;
        float now = Time.time;
        Track(point, now);
        if ((now - lastSentTime) * maxRateHz < 0.999f) return; // (the slack absorbs float rounding of Time.time)
        Send(() => client.SourcePosition(source, point.x, point.y, point.z));
        lastSentTime = now;
    }

    void OnCollisionExit(Collision collision)
    {
        contacts = Math.Max(0, contacts - 1);
        if (contacts > 0 || client == null) return;
        Send(() => client.SourceOn(source, false));
        hasPoint = false;
        Speed = 0f;
    }

    // The mean of the collision's contact points in the layout's frame; false when there is none or it
    // lies outside the +-10 m the server accepts (a layout frame that is far from the contact).
    bool ContactInLayout(Collision collision, out Vector3 point)
    {
        point = Vector3.zero;
        int count = collision.contactCount;
        if (count == 0) return false;
        Vector3 sum = Vector3.zero;
        for (int i = 0; i < count; i++) sum += collision.GetContact(i).point;
        Vector3 world = sum / count;
        point = layoutFrame != null ? layoutFrame.InverseTransformPoint(world) : world;
        float limit = VibsynthCommands.PositionLimit;
        return Mathf.Abs(point.x) <= limit && Mathf.Abs(point.y) <= limit && Mathf.Abs(point.z) <= limit;
    }

    void Track(Vector3 point, float now)
    {
        if (hasPoint && now > lastPointTime) Speed = (point - lastPoint).magnitude / (now - lastPointTime);
        lastPoint = point;
        lastPointTime = now;
        hasPoint = true;
        Position = point;
    }

    // A send that fails (network down) is logged, never thrown into the physics callbacks.
    void Send(Action send)
    {
        try
        {
            send();
        }
        catch (Exception e)
        {
            Log("VibsynthContactSource: " + e.Message);
        }
    }

    void OnServerError(object sender, VibsynthErrorEventArgs e)
    {
        Log("vibsynth refused " + e.Error.Address + ": " + e.Error.Message);
    }

    // At most one line a second (this may run on the client's receive thread: no Unity API but Debug).
    void Log(string text)
    {
        long now = DateTime.UtcNow.Ticks;
        long last = Interlocked.Read(ref lastLogTicks);
        if (now - last < TimeSpan.TicksPerSecond || Interlocked.CompareExchange(ref lastLogTicks, now, last) != last)
        {
            Interlocked.Increment(ref suppressedLogs);
            return;
        }
        int skipped = Interlocked.Exchange(ref suppressedLogs, 0);
        Debug.LogWarning(skipped > 0 ? text + " (" + skipped + " more not shown)" : text);
    }
}
