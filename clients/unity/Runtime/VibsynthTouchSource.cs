// VibsynthTouchSource.cs: a vibsynth touch source that follows a Transform (a fingertip, a controller,
// a tool tip). The source is on while the component is enabled; its position is the Transform's,
// expressed in the actuator layout's frame (metres), sent at most Max Rate times a second and only
// when it moved. The server mixes the source onto the actuators near it (docs/vr.md); with Intensity
// From Speed it derives the intensity from how fast the source moves (its speed curve).

using System;
using UnityEngine;

namespace Vibsynth.Unity
{
    [AddComponentMenu("Vibsynth/Touch Source")]
    public sealed class VibsynthTouchSource : MonoBehaviour
    {
        [Tooltip("The connection to the server (a VibsynthConnection in the scene)")]
        public VibsynthConnection connection;

        [Tooltip("The Transform the source follows (empty: this object's)")]
        public Transform target;

        [Tooltip("The actuator layout's frame: its origin and axes are the layout's x, y, z (metres, scale 1). " +
                 "Empty: world coordinates")]
        public Transform layoutFrame;

        [Tooltip("The spatial source this component drives (1..16); give each one its own")]
        [Range(1, VibsynthCommands.MaxSources)]
        public int source = 1;

        [Tooltip("The source's intensity, 0..1 (not used with Intensity From Speed)")]
        [Range(0f, 1f)]
        public float intensity = 0.8f;

        [Tooltip("The source's balance (knob units; brighter when positive)")]
        [Range(-3.5f, 3.5f)]
        public float balance = 0f;

        [Tooltip("How far from the source it reaches, in metres")]
        [Range(0.001f, 0.5f)]
        public float radius = 0.03f;

        [Tooltip("How the source fades with distance to an actuator")]
        public Rolloff rolloff = Rolloff.Smooth;

        [Tooltip("The server derives the intensity from how fast the source moves (its speed curve)")]
        public bool intensityFromSpeed = true;

        [Tooltip("Position messages per second at most")]
        [Range(10f, 500f)]
        public float maxRateHz = 90f;

        VibsynthClient on; // the client the source was turned on with (null: off)
        Vector3 sent;
        float sentTime = float.NegativeInfinity;

        /// <summary>The last position sent, in the layout's frame (metres).</summary>
        public Vector3 Position { get { return sent; } }

        void Update()
        {
            VibsynthClient client = connection != null ? connection.Client : null;
            Vector3 point;
            if (client == null || !InLayout(out point)) return;
            if (on != client) // first frame with a client (or a new one): everything at once, applied together
            {
                Send(() =>
                {
                    VibsynthBundle start = client.Bundle();
                    start.SourceSpeed(source, intensityFromSpeed);
                    start.SetSource(source, point.x, point.y, point.z, intensity, balance, radius, rolloff, true);
                    start.Send();
                });
                on = client;
            }
            else if ((Time.time - sentTime) * maxRateHz >= 0.999f && (point - sent).magnitude > 1e-5f)
            {
                Send(() => client.SourcePosition(source, point.x, point.y, point.z));
            }
            else
            {
                return;
            }
            sent = point;
            sentTime = Time.time;
        }

        void OnDisable()
        {
            if (on == null) return;
            VibsynthClient client = on;
            on = null;
            Send(() => client.SourceOn(source, false));
        }

        void OnValidate()
        {
            source = Mathf.Clamp(source, 1, VibsynthCommands.MaxSources);
            radius = Mathf.Clamp(radius, 0.001f, VibsynthCommands.PositionLimit);
        }

        // The followed Transform's position in the layout's frame; false beyond the server's +-10 m.
        bool InLayout(out Vector3 point)
        {
            Vector3 world = (target != null ? target : transform).position;
            point = layoutFrame != null ? layoutFrame.InverseTransformPoint(world) : world;
            float limit = VibsynthCommands.PositionLimit;
            return Mathf.Abs(point.x) <= limit && Mathf.Abs(point.y) <= limit && Mathf.Abs(point.z) <= limit;
        }

        static void Send(Action send)
        {
            try
            {
                send();
            }
            catch (ObjectDisposedException) // the connection closed first (leaving the scene): nothing to tell
            {
            }
            catch (Exception e) // a network error is logged, never thrown into Update
            {
                Debug.LogWarning("VibsynthTouchSource: " + e.Message);
            }
        }
    }
}
