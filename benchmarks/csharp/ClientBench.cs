// ClientBench.cs: latency of clients/csharp/VibsynthClient.cs against a running server, for
// benchmarks/bench_csharp_client.py. Usage: mono ClientBench.exe PORT TRIALS. Prints `name=v1,v2,...`
// lines of per-trial times in microseconds (Stopwatch), and `name.mismatched=N` for value checks.

using System;
using System.Collections.Generic;
using System.Diagnostics;
using System.Globalization;
using System.Text;
using System.Threading.Tasks;
using Vibsynth;

static class ClientBench
{
    static readonly CultureInfo Inv = CultureInfo.InvariantCulture;

    static double Micros(long ticks) { return ticks * 1e6 / Stopwatch.Frequency; }

    static void Report(string name, List<double> samples)
    {
        var text = new StringBuilder();
        foreach (double v in samples) text.Append(text.Length == 0 ? "" : ",").Append(v.ToString("0.###", Inv));
        Console.WriteLine(name + "=" + text);
    }

    static int Main(string[] args)
    {
        int port = int.Parse(args[0], Inv);
        int trials = int.Parse(args[1], Inv);
        int warmup = Math.Max(50, trials / 10);
        using (var client = new VibsynthClient("127.0.0.1", port))
        {
            client.Timeout = TimeSpan.FromSeconds(5);
            client.SetGlide(0f);
            client.SetTexture(1, 0.5f, 0f);
            client.Sync();
            var get = new List<double>();
            var ping = new List<double>();
            var setGet = new List<double>();
            var setCall = new List<double>();
            var awaited = new List<double>();
            int mismatched = 0;
            for (int i = -warmup; i < trials; i++)
            {
                long t0 = Stopwatch.GetTimestamp();
                client.GetIntensity(1);
                long t1 = Stopwatch.GetTimestamp();
                client.Ping();
                long t2 = Stopwatch.GetTimestamp();
                float value = (i & 1) == 0 ? 0.25f : 0.75f;
                long t3 = Stopwatch.GetTimestamp();
                client.SetIntensity(1, value);
                long t4 = Stopwatch.GetTimestamp();
                float back = client.GetIntensity(1);
                long t5 = Stopwatch.GetTimestamp();
                if (back != value) mismatched++;
                if (i < 0) continue;
                get.Add(Micros(t1 - t0));
                ping.Add(Micros(t2 - t1));
                setCall.Add(Micros(t4 - t3));
                setGet.Add(Micros(t5 - t3));
            }
            // awaited on the thread pool, as an async method in an app without a synchronization context
            Task.Run(async () =>
            {
                for (int i = -warmup; i < trials; i++)
                {
                    long t0 = Stopwatch.GetTimestamp();
                    await client.GetIntensityAsync(1);
                    long t1 = Stopwatch.GetTimestamp();
                    if (i >= 0) awaited.Add(Micros(t1 - t0));
                }
            }).Wait();
            // many queries in flight at once
            const int inFlight = 1000;
            var pipelined = new List<double>();
            for (int round = 0; round < 5; round++)
            {
                var tasks = new Task<float>[inFlight];
                long t0 = Stopwatch.GetTimestamp();
                for (int i = 0; i < inFlight; i++) tasks[i] = client.GetIntensityAsync(1);
                Task.WaitAll(tasks);
                pipelined.Add(Micros(Stopwatch.GetTimestamp() - t0));
            }
            Report("get", get);
            Report("get_await", awaited);
            Report("ping", ping);
            Report("set_call", setCall);
            Report("set_get", setGet);
            Report("pipelined_1000", pipelined);
            Console.WriteLine("set_get.mismatched=" + mismatched.ToString(Inv));
            Console.WriteLine("malformed=" + client.Malformed.ToString(Inv));
        }
        return 0;
    }
}
