// VibsynthClipTrigger.cs: plays a vibsynth clip (docs/clips.md) when something hits this object, as
// loud as the hit: the gain grows with the impact's speed from Min Speed (silent) to Full Speed (Max
// Gain). Works with colliders (OnCollisionEnter: the relative velocity of the hit) and triggers
// (OnTriggerEnter: the entering body's velocity, when it has a Rigidbody).

using System;
using UnityEngine;

namespace Vibsynth.Unity
{
    [AddComponentMenu("Vibsynth/Clip Trigger")]
    public sealed class VibsynthClipTrigger : MonoBehaviour
    {
        [Tooltip("The connection to the server (a VibsynthConnection in the scene)")]
        public VibsynthConnection connection;

        [Tooltip("The clip to play (`vibsynth clip list`), e.g. impact")]
        public string clip = "impact";

        [Tooltip("The actuator channel that plays it (1..64); 0: every channel")]
        [Range(0, VibsynthCommands.MaxChannels)]
        public int channel = 0;

        [Tooltip("Impacts slower than this (m/s) play nothing")]
        public float minSpeed = 0.05f;

        [Tooltip("Impacts this fast (m/s) or faster play at Max Gain")]
        public float fullSpeed = 3f;

        [Tooltip("The clip's gain at Full Speed (the server takes 0..4)")]
        [Range(0f, VibsynthCommands.MaxClipGain)]
        public float maxGain = 1f;

        /// <summary>The gain of the last clip played (0 before any).</summary>
        public float LastGain { get; private set; }

        void OnCollisionEnter(Collision collision)
        {
            Play(collision.relativeVelocity.magnitude);
        }

        void OnTriggerEnter(Collider other)
        {
            Rigidbody body = other.attachedRigidbody;
            if (body != null) Play(body.velocity.magnitude);
        }

        /// <summary>The gain of an impact at <paramref name="speed"/> m/s (0 below Min Speed).</summary>
        public float GainFor(float speed)
        {
            if (!(speed >= minSpeed)) return 0f; // (also NaN)
            float span = Mathf.Max(fullSpeed - minSpeed, 1e-3f);
            return maxGain * Mathf.Clamp01((speed - minSpeed) / span);
        }

        /// <summary>Play the clip for an impact at <paramref name="speed"/> m/s.</summary>
        public void Play(float speed)
        {
            VibsynthClient client = connection != null ? connection.Client : null;
            float gain = GainFor(speed);
            if (client == null || gain <= 0f) return;
            try
            {
                if (channel > 0) client.PlayClip(channel, clip, gain);
                else client.PlayClipAll(clip, gain);
                LastGain = gain;
            }
            catch (Exception e) // a bad name or a network error: logged, never thrown into physics
            {
                Debug.LogWarning("VibsynthClipTrigger: " + e.Message);
            }
        }
    }
}
