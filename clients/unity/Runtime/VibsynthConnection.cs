// VibsynthConnection.cs: one connection to a running `vibsynth serve`, shared by the package's other
// components (VibsynthTouchSource, VibsynthClipTrigger). Connects to a host and port, or finds the
// server on the network by discovery (mDNS + OSCQuery, VibsynthDiscovery) without blocking a frame.
// Thin on purpose: everything it does is a VibsynthClient call (Client/VibsynthClient.cs).

using System;
using System.Threading.Tasks;
using UnityEngine;

namespace Vibsynth.Unity
{
    [AddComponentMenu("Vibsynth/Connection")]
    [DisallowMultipleComponent]
    public sealed class VibsynthConnection : MonoBehaviour
    {
        [Tooltip("Find the server on the network (mDNS + OSCQuery) instead of the address below")]
        public bool useDiscovery;

        [Tooltip("With discovery: the first server whose name contains this (empty: any)")]
        public string serviceName = "";

        [Tooltip("With discovery: how long to look, in seconds")]
        [Range(0.25f, 10f)]
        public float discoverySeconds = 2f;

        [Tooltip("Host name or IP address of the machine running `vibsynth serve`")]
        public string host = "127.0.0.1";

        [Tooltip("The server's UDP port (osc.port)")]
        public int port = VibsynthClient.DefaultPort;

        [Tooltip("The server's address prefix (osc.prefix)")]
        public string prefix = VibsynthClient.DefaultPrefix;

        VibsynthClient client;
        Task<VibsynthClient> discovering;

        /// <summary>The connected client, or null (not enabled yet, or discovery still looking / found none).</summary>
        public VibsynthClient Client { get { return client; } }

        /// <summary>Raised on the main thread once <see cref="Client"/> is set.</summary>
        public event Action<VibsynthClient> Connected;

        void OnEnable()
        {
            if (useDiscovery)
            {
                string name = string.IsNullOrEmpty(serviceName) ? null : serviceName;
                TimeSpan timeout = TimeSpan.FromSeconds(discoverySeconds);
                discovering = Task.Run(() => VibsynthDiscovery.Connect(name, timeout)); // blocks a worker, not the frame
                return;
            }
            try
            {
                Use(new VibsynthClient(host, port, prefix));
            }
            catch (Exception e)
            {
                Debug.LogError("VibsynthConnection: cannot reach " + host + ":" + port + ": " + e.Message);
            }
        }

        void Update()
        {
            if (discovering == null || !discovering.IsCompleted) return;
            Task<VibsynthClient> done = discovering;
            discovering = null;
            if (done.Status == TaskStatus.RanToCompletion) Use(done.Result);
            else Debug.LogError("VibsynthConnection: no vibsynth server found: " + Reason(done.Exception));
        }

        void OnDisable()
        {
            if (discovering != null)
            {
                Task<VibsynthClient> pending = discovering; // found after all: closed, not leaked
                pending.ContinueWith(t => { if (t.Status == TaskStatus.RanToCompletion) t.Result.Dispose(); });
                discovering = null;
            }
            if (client == null) return;
            client.Dispose();
            client = null;
        }

        void Use(VibsynthClient found)
        {
            client = found;
            client.ErrorReceived += (sender, e) => Debug.LogWarning("vibsynth refused " + e.Error.Address + ": " + e.Error.Message);
            if (Connected != null) Connected(client);
        }

        static string Reason(AggregateException e)
        {
            if (e == null) return "cancelled";
            return e.InnerException != null ? e.InnerException.Message : e.Message;
        }
    }
}
