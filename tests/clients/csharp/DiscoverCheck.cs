// The C# client's discovery, run by tests/clients/netns_discover.py inside a network namespace:
// Discover() lists the OSCQuery services (key=value lines: an endpoint, or why it has none), Connect(name) reads channel 1's intensity.
using System;
using System.Globalization;
using Vibsynth;

public static class DiscoverCheck
{
    public static int Main(string[] args)
    {
        var services = VibsynthDiscovery.Discover(TimeSpan.FromSeconds(2));
        Console.WriteLine("found=" + services.Count);
        foreach (var s in services)
        {
            Console.WriteLine("service=" + s.Name);
            Console.WriteLine(s.Name + ".url=" + s.OscQueryUrl);
            if (s.Resolved)
                Console.WriteLine(s.Name + ".osc=" + s.OscHost + ":" + s.OscPort.ToString(CultureInfo.InvariantCulture));
            else
                Console.WriteLine(s.Name + ".unresolved=" + s.Unresolved);
            Console.WriteLine(s.Name + ".transport=" + s.OscTransport);
        }
        using (var client = VibsynthDiscovery.Connect(args[0], TimeSpan.FromSeconds(2)))
            Console.WriteLine("intensity=" + client.GetIntensity(1).ToString("R", CultureInfo.InvariantCulture));
        try
        {
            VibsynthDiscovery.Connect("no such service", TimeSpan.FromSeconds(1));
        }
        catch (VibsynthException exc)
        {
            Console.WriteLine("missing=" + exc.Message);
        }
        return 0;
    }
}
