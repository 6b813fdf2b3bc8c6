// The C# client's discovery against a scripted mDNS responder and HOST_INFO server (tests/clients/netns_resolve.py)
// whose answers come late or never. Arguments: TIMEOUT_S NAME. Prints key=value lines: what Discover(TIMEOUT)
// listed (an endpoint, or why none and what reading it does) and what Connect(NAME, TIMEOUT) returned.
using System;
using System.Globalization;
using Vibsynth;

public static class ResolveCheck
{
    public static int Main(string[] args)
    {
        var timeout = TimeSpan.FromSeconds(double.Parse(args[0], CultureInfo.InvariantCulture));
        var services = VibsynthDiscovery.Discover(timeout);
        Console.WriteLine("found=" + services.Count);
        foreach (var s in services)
        {
            Console.WriteLine(s.Name + ".resolved=" + (s.Resolved ? "true" : "false"));
            Console.WriteLine(s.Name + ".text=" + s);
            if (s.Resolved)
            {
                Console.WriteLine(s.Name + ".osc=" + s.OscHost + ":" + s.OscPort.ToString(CultureInfo.InvariantCulture));
                continue;
            }
            Console.WriteLine(s.Name + ".unresolved=" + s.Unresolved);
            try
            {
                Console.WriteLine(s.Name + ".port=" + s.OscPort.ToString(CultureInfo.InvariantCulture));
            }
            catch (VibsynthException exc)
            {
                Console.WriteLine(s.Name + ".port_error=" + exc.Message);
            }
        }
        try
        {
            using (var client = VibsynthDiscovery.Connect(args[1], timeout))
                Console.WriteLine("connected=" + client.Host + ":" + client.Port.ToString(CultureInfo.InvariantCulture));
        }
        catch (VibsynthException exc)
        {
            Console.WriteLine("connect_error=" + exc.Message);
        }
        return 0;
    }
}
