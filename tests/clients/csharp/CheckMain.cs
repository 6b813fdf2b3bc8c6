// CheckMain.cs: what the test programs (ClientCheck.cs, UnityCheck.cs) share: running one command named
// on the command line, and reporting observations as `key=value` lines for the Python tests.

using System;
using System.Collections.Generic;
using System.Globalization;
using System.Threading;
using Vibsynth;

static class CheckMain
{
    public static readonly CultureInfo Inv = CultureInfo.InvariantCulture;

    // Runs commands[args[0]] with the remaining arguments: exit code 0, 1 with the exception on stderr
    // when it throws, 2 for a wrong command line.
    public static int Run(string[] args, Dictionary<string, Action<string[]>> commands)
    {
        // a decimal comma must not leak into the wire format or the report
        Thread.CurrentThread.CurrentCulture = new CultureInfo("de-DE");
        Action<string[]> command;
        if (args.Length == 0 || !commands.TryGetValue(args[0], out command))
        {
            Console.Error.WriteLine("usage: COMMAND ARGS... with COMMAND one of " + string.Join(", ", new List<string>(commands.Keys).ToArray()));
            return 2;
        }
        var rest = new string[args.Length - 1];
        Array.Copy(args, 1, rest, 0, rest.Length);
        try
        {
            command(rest);
        }
        catch (Exception e)
        {
            Console.Error.WriteLine("FAILED: " + e);
            return 1;
        }
        return 0;
    }

    public static int Int(string text) { return int.Parse(text, Inv); }

    // What a call did: `key=no exception`, or `key.type` and `key.message` of what it threw (a server
    // refusal also: `key.address`, `key.count` and each `key.error{i}` in order).
    public static void Report(string key, Action action)
    {
        try
        {
            action();
            Say(key, "no exception");
        }
        catch (Exception e)
        {
            Exception inner = e is AggregateException ? ((AggregateException)e).InnerException : e;
            var server = inner as VibsynthServerException;
            if (server != null)
            {
                Say(key + ".type", "VibsynthServerException");
                Say(key + ".address", server.Address);
                Say(key + ".message", server.ServerMessage);
                Say(key + ".count", server.Errors.Count);
                for (int i = 0; i < server.Errors.Count; i++) Say(key + ".error" + i, server.Errors[i]);
            }
            else
            {
                Say(key + ".type", inner.GetType().Name);
                Say(key + ".message", inner.Message);
            }
        }
    }

    // One observation; floats round-trip exactly ("R"), booleans as true/false, newlines escaped.
    public static void Say(string key, object value)
    {
        string text;
        if (value is float) text = ((float)value).ToString("R", Inv);
        else if (value is double) text = ((double)value).ToString("R", Inv);
        else if (value is bool) text = (bool)value ? "true" : "false";
        else if (value == null) text = "null";
        else text = Convert.ToString(value, Inv);
        Console.WriteLine(key + "=" + text.Replace("\n", "\\n"));
    }
}
