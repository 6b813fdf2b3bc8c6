// Generated from clients/csharp/VibsynthClient.cs by scripts/sync_unity.py: edit there, then run the script.

// VibsynthClient.cs: a C# client for a running `vibsynth serve` (OSC 1.0 over UDP).
//
// One file, no dependencies: drop it into a Unity project's Assets folder, or compile it with
// any C# 6 compiler against .NET Standard 2.0 / .NET Framework 4.6 or later (mono's `mcs`,
// `dotnet`, Unity's Roslyn). The address space and reply formats are the server's
// (docs/osc.md in the vibsynth repository); README.md beside this file shows the whole API.
//
//   using (var client = new Vibsynth.VibsynthClient("127.0.0.1", 9570))
//   {
//       client.SetTexture(2, 0.6f, -0.5f);          // channel 2: intensity, balance
//       float level = client.GetIntensity(2);        // waits for the server's reply
//       float again = await client.GetIntensityAsync(2);
//   }
//
// Threading: every method may be called from any thread (Unity's main thread included).
// Setters send one datagram and return at once. Queries wait for their reply, matched by a
// background receive thread; the Async variants never block, the synchronous ones block the
// caller up to the timeout. Events are raised on the receive thread.

using System;
using System.Collections.Generic;
using System.Collections.ObjectModel;
using System.Diagnostics;
using System.Globalization;
using System.Net;
using System.Net.Sockets;
using System.Runtime.InteropServices;
using System.Text;
using System.Threading;
using System.Threading.Tasks;

namespace Vibsynth
{
    // ================================================================== exceptions

    /// <summary>Base class of the errors this client raises (besides ArgumentException for bad arguments).</summary>
    public class VibsynthException : Exception
    {
        public VibsynthException(string message) : base(message) { }
        public VibsynthException(string message, Exception inner) : base(message, inner) { }
    }

    /// <summary>No matching reply arrived within the timeout (server not running, wrong port, reply lost).</summary>
    public sealed class VibsynthTimeoutException : VibsynthException
    {
        /// <summary>The OSC address of the request that got no answer.</summary>
        public string Request { get; private set; }
        /// <summary>How long the client waited.</summary>
        public TimeSpan Timeout { get; private set; }
        /// <summary>The server's host, as given to the client.</summary>
        public string Host { get; private set; }
        /// <summary>The server's UDP port.</summary>
        public int Port { get; private set; }

        public VibsynthTimeoutException(string host, int port, string request, TimeSpan timeout)
            : base(string.Format(CultureInfo.InvariantCulture, "no reply from {0}:{1} to {2} within {3:0.###} s",
                host, port, request, timeout.TotalSeconds))
        {
            Host = host;
            Port = port;
            Request = request;
            Timeout = timeout;
        }
    }

    /// <summary>One refusal from the server: <c>/vibsynth/error s address s message</c>.</summary>
    public sealed class VibsynthError
    {
        /// <summary>The address of the refused message, e.g. <c>/vibsynth/intensity</c>.</summary>
        public string Address { get; private set; }
        /// <summary>The server's text, e.g. <c>intensity 1.5 is outside the allowed range [0, 1]</c>.</summary>
        public string Message { get; private set; }

        public VibsynthError(string address, string message)
        {
            Address = address;
            Message = message;
        }

        public override string ToString() { return Address + ": " + Message; }
    }

    /// <summary>The server refused a request; <see cref="ServerMessage"/> is its error reply's text.</summary>
    public sealed class VibsynthServerException : VibsynthException
    {
        /// <summary>The address the server refused (the first one when there are several).</summary>
        public string Address { get; private set; }
        /// <summary>The server's error text (the first one when there are several).</summary>
        public string ServerMessage { get; private set; }
        /// <summary>Every refusal this exception reports (one, except from <c>Sync</c>).</summary>
        public ReadOnlyCollection<VibsynthError> Errors { get; private set; }

        public VibsynthServerException(IList<VibsynthError> errors)
            : base(Describe(errors))
        {
            Errors = new ReadOnlyCollection<VibsynthError>(new List<VibsynthError>(errors));
            Address = errors[0].Address;
            ServerMessage = errors[0].Message;
        }

        static string Describe(IList<VibsynthError> errors)
        {
            if (errors == null || errors.Count == 0)
                throw new ArgumentException("a server exception needs at least one error", "errors");
            string text = errors[0].Address + ": " + errors[0].Message;
            return errors.Count == 1 ? text : text + string.Format(CultureInfo.InvariantCulture,
                " (and {0} more refusal{1})", errors.Count - 1, errors.Count == 2 ? "" : "s");
        }
    }

    // ================================================================== OSC values

    /// <summary>An OSC time tag: 64-bit NTP time (seconds since 1900 in the high 32 bits, fraction in the low 32).</summary>
    public struct OscTimeTag : IEquatable<OscTimeTag>
    {
        /// <summary>The raw 64-bit value.</summary>
        public readonly ulong Value;

        /// <summary>The special time tag 1: "immediately".</summary>
        public static readonly OscTimeTag Immediately = new OscTimeTag(1);

        static readonly DateTime NtpEpoch = new DateTime(1900, 1, 1, 0, 0, 0, DateTimeKind.Utc);

        public OscTimeTag(ulong value) { Value = value; }

        /// <summary>The time tag of a point in time (a Local or Unspecified time is read as local time).</summary>
        /// <exception cref="ArgumentOutOfRangeException">Before 1900 or beyond 2036 (NTP era 0).</exception>
        public static OscTimeTag FromDateTime(DateTime time)
        {
            DateTime utc = time.Kind == DateTimeKind.Utc ? time : time.ToUniversalTime();
            long ticks = (utc - NtpEpoch).Ticks;
            if (ticks < 0 || ticks / TimeSpan.TicksPerSecond > uint.MaxValue)
                throw new ArgumentOutOfRangeException("time", time, "an OSC time tag spans 1900-01-01 to 2036-02-07 (UTC)");
            ulong seconds = (ulong)(ticks / TimeSpan.TicksPerSecond);
            ulong rest = (ulong)(ticks % TimeSpan.TicksPerSecond);
            ulong fraction = (rest << 32) / (ulong)TimeSpan.TicksPerSecond;
            return new OscTimeTag((seconds << 32) | fraction);
        }

        /// <summary>The current wall-clock time (see <see cref="WallClock"/>).</summary>
        public static OscTimeTag Now() { return FromDateTime(WallClock.UtcNow()); }

        /// <summary>The wall-clock time <paramref name="seconds"/> from now.</summary>
        public static OscTimeTag FromNow(double seconds)
        {
            return FromDateTime(WallClock.UtcNow().AddTicks((long)Math.Round(seconds * TimeSpan.TicksPerSecond)));
        }

        /// <summary>The UTC time this tag stands for (to the 100 ns tick).</summary>
        public DateTime ToDateTime()
        {
            ulong seconds = Value >> 32;
            ulong fraction = Value & 0xFFFFFFFFUL;
            long ticks = (long)seconds * TimeSpan.TicksPerSecond + (long)((fraction * (ulong)TimeSpan.TicksPerSecond) >> 32);
            return NtpEpoch.AddTicks(ticks);
        }

        public bool Equals(OscTimeTag other) { return Value == other.Value; }
        public override bool Equals(object obj) { return obj is OscTimeTag && Equals((OscTimeTag)obj); }
        public override int GetHashCode() { return Value.GetHashCode(); }
        public override string ToString() { return Value == 1 ? "immediately" : ToDateTime().ToString("o", CultureInfo.InvariantCulture); }
    }

    /// <summary>
    /// The wall clock used for time tags: <see cref="DateTime.UtcNow"/> refined by <see cref="Stopwatch"/>.
    /// </summary>
    /// <remarks>
    /// The server converts a time tag with its own system clock, so both machines' clocks must agree
    /// (NTP). On some runtimes DateTime.UtcNow advances in 1-16 ms steps; this clock keeps an anchor
    /// (system time, stopwatch) and adds the stopwatch's elapsed time, so time tags have sub-millisecond
    /// resolution. It re-anchors whenever the system clock is more than 20 ms away from its estimate
    /// (the clock was set, or slewed that far).
    /// </remarks>
    public static class WallClock
    {
        static readonly object Gate = new object();
        static DateTime anchorTime = DateTime.UtcNow;
        static long anchorStamp = Stopwatch.GetTimestamp();
        const double ResyncSeconds = 0.020;

        /// <summary>The current UTC time with stopwatch resolution.</summary>
        public static DateTime UtcNow()
        {
            lock (Gate)
            {
                long stamp = Stopwatch.GetTimestamp();
                DateTime system = DateTime.UtcNow;
                double elapsed = (stamp - anchorStamp) / (double)Stopwatch.Frequency;
                DateTime estimate = anchorTime.AddTicks((long)(elapsed * TimeSpan.TicksPerSecond));
                if (Math.Abs((system - estimate).TotalSeconds) > ResyncSeconds)
                {
                    anchorTime = system;
                    anchorStamp = stamp;
                    return system;
                }
                return estimate;
            }
        }
    }

    /// <summary>An OSC blob argument (type b) is a byte[]; an OSC "nil" (N) is null; "infinitum" (I) is this.</summary>
    public sealed class OscInfinitum
    {
        public static readonly OscInfinitum Value = new OscInfinitum();
        OscInfinitum() { }
        public override string ToString() { return "Infinitum"; }
    }

    /// <summary>One OSC message: an address, type tags and argument values.</summary>
    /// <remarks>
    /// Argument types: i = int, h = long, f = float, d = double, s/S = string, b = byte[],
    /// t = <see cref="OscTimeTag"/>, T/F = bool, N = null, I = <see cref="OscInfinitum"/>, c = char.
    /// </remarks>
    public sealed class OscMessage
    {
        /// <summary>The OSC address (or address pattern), e.g. <c>/vibsynth/ch/1/intensity</c>.</summary>
        public string Address { get; private set; }
        /// <summary>The type tags without the leading comma, e.g. <c>ff</c>.</summary>
        public string TypeTags { get; private set; }
        /// <summary>The argument values, one per type tag.</summary>
        public ReadOnlyCollection<object> Arguments { get; private set; }

        /// <summary>A message with the given tags and values (checked against each other).</summary>
        /// <exception cref="ArgumentException">A bad address, an unknown tag or a value that does not fit its tag.</exception>
        public OscMessage(string address, string typeTags, IList<object> arguments)
        {
            Osc.CheckAddress(address);
            if (typeTags == null) throw new ArgumentNullException("typeTags");
            if (arguments == null) throw new ArgumentNullException("arguments");
            if (typeTags.Length != arguments.Count)
                throw new ArgumentException(string.Format(CultureInfo.InvariantCulture,
                    "{0} type tags for {1} arguments", typeTags.Length, arguments.Count), "typeTags");
            for (int i = 0; i < typeTags.Length; i++) Osc.CheckValue(typeTags[i], arguments[i]);
            Address = address;
            TypeTags = typeTags;
            Arguments = new ReadOnlyCollection<object>(new List<object>(arguments));
        }

        /// <summary>A message whose type tags are inferred from the values (see <see cref="Osc.TypeTagOf"/>).</summary>
        public OscMessage(string address, params object[] arguments)
            : this(address, Osc.TypeTagsOf(arguments ?? new object[] { null }), arguments ?? new object[] { null }) { }

        internal static OscMessage Trusted(string address, string tags, object[] args)
        {
            var message = new OscMessage();
            message.Address = address;
            message.TypeTags = tags;
            message.Arguments = new ReadOnlyCollection<object>(args);
            return message;
        }

        OscMessage() { }

        /// <summary>How many arguments.</summary>
        public int Count { get { return TypeTags.Length; } }

        /// <summary>Is argument <paramref name="index"/> a number (i, h, f or d)?</summary>
        public bool IsNumber(int index)
        {
            return index >= 0 && index < TypeTags.Length && "ihfd".IndexOf(TypeTags[index]) >= 0;
        }

        /// <summary>Is argument <paramref name="index"/> a string (s or S)?</summary>
        public bool IsString(int index)
        {
            return index >= 0 && index < TypeTags.Length && (TypeTags[index] == 's' || TypeTags[index] == 'S');
        }

        /// <summary>Argument <paramref name="index"/> as a float (from i, h, f or d).</summary>
        public float GetFloat(int index) { return (float)GetDouble(index); }

        /// <summary>Argument <paramref name="index"/> as a double (from i, h, f or d).</summary>
        public double GetDouble(int index)
        {
            if (!IsNumber(index)) throw WrongType(index, "a number");
            return Convert.ToDouble(Arguments[index], CultureInfo.InvariantCulture);
        }

        /// <summary>Argument <paramref name="index"/> as an int (from i, or T/F as 1/0).</summary>
        public int GetInt(int index)
        {
            if (index >= 0 && index < TypeTags.Length)
            {
                char tag = TypeTags[index];
                if (tag == 'i') return (int)Arguments[index];
                if (tag == 'T') return 1;
                if (tag == 'F') return 0;
            }
            throw WrongType(index, "an int");
        }

        /// <summary>Argument <paramref name="index"/> as a string (from s or S).</summary>
        public string GetString(int index)
        {
            if (!IsString(index)) throw WrongType(index, "a string");
            return (string)Arguments[index];
        }

        InvalidCastException WrongType(int index, string what)
        {
            string found = index >= 0 && index < TypeTags.Length ? "type '" + TypeTags[index] + "'" : "no such argument";
            return new InvalidCastException(string.Format(CultureInfo.InvariantCulture,
                "{0} argument {1} is not {2} ({3})", Address, index, what, found));
        }

        /// <summary>Like oscdump: <c>/vibsynth/ch/1/intensity f 0.5</c>.</summary>
        public override string ToString()
        {
            var text = new StringBuilder(Address);
            text.Append(' ').Append(TypeTags.Length == 0 ? "-" : TypeTags);
            foreach (object value in Arguments)
            {
                text.Append(' ');
                if (value == null) text.Append("Nil");
                else if (value is string) text.Append('"').Append((string)value).Append('"');
                else if (value is byte[]) text.Append("<blob ").Append(((byte[])value).Length).Append(" bytes>");
                else if (value is float) text.Append(((float)value).ToString("R", CultureInfo.InvariantCulture));
                else if (value is double) text.Append(((double)value).ToString("R", CultureInfo.InvariantCulture));
                else text.Append(Convert.ToString(value, CultureInfo.InvariantCulture));
            }
            return text.ToString();
        }
    }

    /// <summary>A received message with the time tag of the bundle it came in (Immediately when none).</summary>
    public sealed class OscReceived
    {
        public OscMessage Message { get; private set; }
        public OscTimeTag TimeTag { get; private set; }
        internal OscReceived(OscMessage message, OscTimeTag timeTag) { Message = message; TimeTag = timeTag; }
    }

    // ================================================================== OSC 1.0 wire format

    /// <summary>OSC 1.0 encoding and a strict, bounded decoder.</summary>
    public static class Osc
    {
        /// <summary>Largest UDP payload over IPv4; larger packets are refused.</summary>
        public const int MaxDatagram = 65507;
        /// <summary>Bundles nested deeper are refused by the decoder (the server's limit too).</summary>
        public const int MaxBundleDepth = 8;

        static readonly byte[] BundleHead = Encoding.ASCII.GetBytes("#bundle\0");
        static readonly UTF8Encoding Utf8 = new UTF8Encoding(false, true);

        [StructLayout(LayoutKind.Explicit)]
        struct FloatBits
        {
            [FieldOffset(0)] public float Float;
            [FieldOffset(0)] public int Int;
        }

        // -------------------------------------------------------------- encoding
        /// <summary>Encode a message; type tags are inferred from the values (<see cref="TypeTagOf"/>).</summary>
        public static byte[] EncodeMessage(string address, params object[] arguments)
        {
            if (arguments == null) arguments = new object[] { null };
            return EncodeMessage(address, TypeTagsOf(arguments), arguments);
        }

        /// <summary>Encode a message with explicit type tags, e.g. <c>("/x", "fi", 0.5f, 3)</c>.</summary>
        /// <exception cref="ArgumentException">A bad address, an unknown tag or a value that does not fit its tag.</exception>
        public static byte[] EncodeMessage(string address, string typeTags, IList<object> arguments)
        {
            CheckAddress(address);
            if (typeTags == null) throw new ArgumentNullException("typeTags");
            if (arguments == null) throw new ArgumentNullException("arguments");
            if (typeTags.Length != arguments.Count)
                throw new ArgumentException(string.Format(CultureInfo.InvariantCulture,
                    "{0} type tags for {1} arguments", typeTags.Length, arguments.Count), "typeTags");
            var writer = new Writer(64);
            writer.String(address);
            writer.String("," + typeTags);
            for (int i = 0; i < typeTags.Length; i++)
            {
                char tag = typeTags[i];
                object value = arguments[i];
                CheckValue(tag, value);
                switch (tag)
                {
                    case 'i': writer.Int32((int)value); break;
                    case 'c': writer.Int32((char)value); break;
                    case 'h': writer.Int64((long)value); break;
                    case 't': writer.Int64((long)((OscTimeTag)value).Value); break;
                    case 'f': writer.Float32((float)value); break;
                    case 'd': writer.Int64(BitConverter.DoubleToInt64Bits((double)value)); break;
                    case 's': case 'S': writer.String((string)value); break;
                    case 'b': writer.Blob((byte[])value); break;
                    default: break; // T F N I: no data
                }
            }
            return writer.ToArray();
        }

        /// <summary>Encode a message object.</summary>
        public static byte[] Encode(OscMessage message)
        {
            if (message == null) throw new ArgumentNullException("message");
            return EncodeMessage(message.Address, message.TypeTags, message.Arguments);
        }

        /// <summary>Encode a bundle of already encoded elements (messages or bundles).</summary>
        /// <exception cref="ArgumentException">An element that is not an encoded OSC packet.</exception>
        public static byte[] EncodeBundle(OscTimeTag timeTag, IList<byte[]> elements)
        {
            if (elements == null) throw new ArgumentNullException("elements");
            int size = 16;
            foreach (byte[] element in elements)
            {
                if (element == null || element.Length == 0 || element.Length % 4 != 0)
                    throw new ArgumentException("a bundle element is an encoded OSC message or bundle (a non-empty multiple of 4 bytes)", "elements");
                size += 4 + element.Length;
            }
            var writer = new Writer(size);
            writer.Bytes(BundleHead, 0, BundleHead.Length);
            writer.Int64((long)timeTag.Value);
            foreach (byte[] element in elements)
            {
                writer.Int32(element.Length);
                writer.Bytes(element, 0, element.Length);
            }
            return writer.ToArray();
        }

        /// <summary>The type tag for a value: int i, long h, float f, double d, string s, byte[] b, bool T/F,
        /// null N, char c, <see cref="OscTimeTag"/> t, <see cref="OscInfinitum"/> I.</summary>
        /// <exception cref="ArgumentException">Any other type.</exception>
        public static char TypeTagOf(object value)
        {
            if (value == null) return 'N';
            if (value is int) return 'i';
            if (value is float) return 'f';
            if (value is string) return 's';
            if (value is double) return 'd';
            if (value is long) return 'h';
            if (value is bool) return (bool)value ? 'T' : 'F';
            if (value is byte[]) return 'b';
            if (value is char) return 'c';
            if (value is OscTimeTag) return 't';
            if (value is OscInfinitum) return 'I';
            throw new ArgumentException("cannot send a " + value.GetType().Name +
                " as an OSC argument (int, long, float, double, string, byte[], bool, char, OscTimeTag or null)");
        }

        /// <summary>The type tags of several values.</summary>
        public static string TypeTagsOf(IList<object> values)
        {
            var tags = new char[values.Count];
            for (int i = 0; i < tags.Length; i++) tags[i] = TypeTagOf(values[i]);
            return new string(tags);
        }

        internal static void CheckAddress(string address)
        {
            if (address == null) throw new ArgumentNullException("address");
            if (address.Length == 0 || address[0] != '/' || address.IndexOf('\0') >= 0)
                throw new ArgumentException("an OSC address starts with '/' and holds no NUL character, got \"" + address + "\"", "address");
        }

        internal static void CheckValue(char tag, object value)
        {
            bool ok;
            switch (tag)
            {
                case 'i': ok = value is int; break;
                case 'h': ok = value is long; break;
                case 'f': ok = value is float; break;
                case 'd': ok = value is double; break;
                case 's': case 'S': ok = value is string && ((string)value).IndexOf('\0') < 0; break;
                case 'b': ok = value is byte[]; break;
                case 'c': ok = value is char; break;
                case 't': ok = value is OscTimeTag; break;
                case 'T': ok = value is bool && (bool)value; break;
                case 'F': ok = value is bool && !(bool)value; break;
                case 'N': ok = value == null; break;
                case 'I': ok = value is OscInfinitum; break;
                default:
                    throw new ArgumentException("unsupported OSC type tag '" + tag + "' (supported: i h f d s S b c t T F N I)");
            }
            if (!ok)
                throw new ArgumentException(string.Format(CultureInfo.InvariantCulture,
                    "OSC type '{0}' cannot hold {1}", tag, value == null ? "null" : value.GetType().Name + " " + value));
        }

        sealed class Writer
        {
            byte[] buffer;
            int length;

            public Writer(int capacity) { buffer = new byte[Math.Max(capacity, 16)]; }

            void Room(int more)
            {
                if (length + more <= buffer.Length) return;
                var bigger = new byte[Math.Max(buffer.Length * 2, length + more)];
                Buffer.BlockCopy(buffer, 0, bigger, 0, length);
                buffer = bigger;
            }

            public void Bytes(byte[] data, int offset, int count)
            {
                Room(count);
                Buffer.BlockCopy(data, offset, buffer, length, count);
                length += count;
            }

            public void Int32(int value)
            {
                Room(4);
                buffer[length++] = (byte)(value >> 24);
                buffer[length++] = (byte)(value >> 16);
                buffer[length++] = (byte)(value >> 8);
                buffer[length++] = (byte)value;
            }

            public void Int64(long value)
            {
                Int32((int)(value >> 32));
                Int32((int)value);
            }

            public void Float32(float value)
            {
                var bits = new FloatBits();
                bits.Float = value;
                Int32(bits.Int);
            }

            // UTF-8, then 1..4 NULs: the terminator and the padding to a multiple of 4
            public void String(string text)
            {
                byte[] raw = Utf8.GetBytes(text);
                Bytes(raw, 0, raw.Length);
                Zeros(4 - raw.Length % 4);
            }

            // int32 size, the bytes, then 0..3 NULs to a multiple of 4
            public void Blob(byte[] data)
            {
                Int32(data.Length);
                Bytes(data, 0, data.Length);
                Zeros((4 - data.Length % 4) % 4);
            }

            void Zeros(int count)
            {
                Room(count);
                for (int i = 0; i < count; i++) buffer[length++] = 0;
            }

            public byte[] ToArray()
            {
                var result = new byte[length];
                Buffer.BlockCopy(buffer, 0, result, 0, length);
                return result;
            }
        }

        // -------------------------------------------------------------- decoding
        /// <summary>
        /// The messages of one datagram (bundles flattened, each with its bundle's time tag), or null when it is
        /// not valid OSC 1.0: truncated, bad padding, a type tag not listed in <see cref="OscMessage"/>, arrays,
        /// non-UTF-8 text, bundles nested deeper than <see cref="MaxBundleDepth"/>, element sizes that do not fit.
        /// Never throws for bad input.
        /// </summary>
        public static List<OscReceived> Decode(byte[] data, int offset, int count)
        {
            if (data == null || offset < 0 || count < 0 || offset + count > data.Length) return null;
            var found = new List<OscReceived>();
            try
            {
                return DecodePacket(data, offset, count, OscTimeTag.Immediately, 0, found) ? found : null;
            }
            catch (DecoderFallbackException)
            {
                return null;
            }
        }

        /// <summary>Decode a whole array (see <see cref="Decode(byte[], int, int)"/>).</summary>
        public static List<OscReceived> Decode(byte[] data)
        {
            return data == null ? null : Decode(data, 0, data.Length);
        }

        static bool DecodePacket(byte[] data, int offset, int count, OscTimeTag outer, int depth, List<OscReceived> found)
        {
            if (count == 0 || count % 4 != 0) return false;
            if (data[offset] == (byte)'/')
            {
                OscMessage message = DecodeMessage(data, offset, count);
                if (message == null) return false;
                found.Add(new OscReceived(message, outer));
                return true;
            }
            if (count < 16 || depth >= MaxBundleDepth) return false;
            for (int i = 0; i < BundleHead.Length; i++)
                if (data[offset + i] != BundleHead[i]) return false;
            var tag = new OscTimeTag((ulong)ReadInt64(data, offset + 8));
            if (tag.Value == 1) tag = outer; // "immediately" inside a bundle: the enclosing bundle's time
            int index = offset + 16, end = offset + count;
            while (index < end)
            {
                if (index + 4 > end) return false;
                int size = ReadInt32(data, index);
                index += 4;
                if (size <= 0 || size % 4 != 0 || size > end - index) return false;
                if (!DecodePacket(data, index, size, tag, depth + 1, found)) return false;
                index += size;
            }
            return true;
        }

        static OscMessage DecodeMessage(byte[] data, int offset, int count)
        {
            int end = offset + count;
            int index = offset;
            string address = ReadString(data, ref index, end);
            if (address == null) return null;
            if (index == end) return OscMessage.Trusted(address, "", new object[0]); // no type tag string (pre-1.0)
            string tags = ReadString(data, ref index, end);
            if (tags == null || tags.Length == 0 || tags[0] != ',') return null;
            tags = tags.Substring(1);
            var args = new object[tags.Length];
            for (int i = 0; i < tags.Length; i++)
            {
                switch (tags[i])
                {
                    case 'i':
                        if (index + 4 > end) return null;
                        args[i] = ReadInt32(data, index);
                        index += 4;
                        break;
                    case 'c':
                        if (index + 4 > end) return null;
                        int code = ReadInt32(data, index);
                        if (code < 0 || code > 0xFFFF) return null;
                        args[i] = (char)code;
                        index += 4;
                        break;
                    case 'f':
                        if (index + 4 > end) return null;
                        var bits = new FloatBits();
                        bits.Int = ReadInt32(data, index);
                        args[i] = bits.Float;
                        index += 4;
                        break;
                    case 'h':
                    case 'd':
                    case 't':
                        if (index + 8 > end) return null;
                        long raw = ReadInt64(data, index);
                        index += 8;
                        if (tags[i] == 'h') args[i] = raw;
                        else if (tags[i] == 'd') args[i] = BitConverter.Int64BitsToDouble(raw);
                        else args[i] = new OscTimeTag((ulong)raw);
                        break;
                    case 's':
                    case 'S':
                        string text = ReadString(data, ref index, end);
                        if (text == null) return null;
                        args[i] = text;
                        break;
                    case 'b':
                        if (index + 4 > end) return null;
                        int size = ReadInt32(data, index);
                        index += 4;
                        if (size < 0 || size > end - index) return null;
                        var blob = new byte[size];
                        Buffer.BlockCopy(data, index, blob, 0, size);
                        index += size;
                        int pad = (4 - size % 4) % 4;
                        if (pad > end - index) return null;
                        for (int k = 0; k < pad; k++)
                            if (data[index++] != 0) return null;
                        args[i] = blob;
                        break;
                    case 'T': args[i] = true; break;
                    case 'F': args[i] = false; break;
                    case 'N': args[i] = null; break;
                    case 'I': args[i] = OscInfinitum.Value; break;
                    default: return null;
                }
            }
            return index == end ? OscMessage.Trusted(address, tags, args) : null;
        }

        // A NUL-terminated UTF-8 string padded with NULs to a multiple of 4; null when malformed.
        static string ReadString(byte[] data, ref int index, int end)
        {
            int nul = Array.IndexOf(data, (byte)0, index, end - index);
            if (nul < 0) return null;
            int padded = index + ((nul - index) / 4 + 1) * 4;
            if (padded > end) return null;
            for (int k = nul; k < padded; k++)
                if (data[k] != 0) return null;
            string text = Utf8.GetString(data, index, nul - index);
            index = padded;
            return text;
        }

        static int ReadInt32(byte[] data, int index)
        {
            return (data[index] << 24) | (data[index + 1] << 16) | (data[index + 2] << 8) | data[index + 3];
        }

        static long ReadInt64(byte[] data, int index)
        {
            return ((long)ReadInt32(data, index) << 32) | (uint)ReadInt32(data, index + 4);
        }
    }

    // ================================================================== values the client returns

    /// <summary>A channel's or a source's two knobs.</summary>
    public struct Texture
    {
        /// <summary>0..1 (0 = silence).</summary>
        public readonly float Intensity;
        /// <summary>Knob units: 0 = the mean spectrum, +1/-1 = 98th/2nd percentile, positive = brighter.</summary>
        public readonly float Balance;

        public Texture(float intensity, float balance)
        {
            Intensity = intensity;
            Balance = balance;
        }

        public override string ToString()
        {
            return string.Format(CultureInfo.InvariantCulture, "(intensity {0}, balance {1})", Intensity, Balance);
        }
    }

    /// <summary>What clip a channel plays (<c>/vibsynth/ch/{n}/get clip</c>).</summary>
    public struct ClipState
    {
        /// <summary>The clip's name, or null when the channel plays none.</summary>
        public readonly string Name;
        /// <summary>Where it is, in the clip's own time (ms; 0 for a clip timetagged to start later).</summary>
        public readonly float PositionMs;
        /// <summary>Repeats of its loop region still to come (-1 = until stopped).</summary>
        public readonly int LoopsLeft;

        public ClipState(string name, float positionMs, int loopsLeft)
        {
            Name = string.IsNullOrEmpty(name) ? null : name;
            PositionMs = positionMs;
            LoopsLeft = loopsLeft;
        }

        /// <summary>Does the channel play a clip?</summary>
        public bool IsPlaying { get { return Name != null; } }

        public override string ToString()
        {
            return Name == null ? "(no clip)" : string.Format(CultureInfo.InvariantCulture,
                "({0} at {1} ms, {2} loops left)", Name, PositionMs, LoopsLeft);
        }
    }

    /// <summary>How a source's weight falls off with the distance d to an actuator (docs/vr.md).</summary>
    public enum Rolloff
    {
        /// <summary>w = max(0, 1 - d/r).</summary>
        Linear,
        /// <summary>Raised cosine: w = (1 + cos(pi d/r)) / 2 inside r, 0 outside.</summary>
        Smooth,
        /// <summary>w = 1 / (1 + (d/r)^2), no cut-off.</summary>
        InverseSquare,
        /// <summary>Energy-preserving panning between the two or three nearest actuators.</summary>
        Phantom,
    }

    /// <summary>The server's <c>/status.reply</c>: key/value pairs in the server's order (docs/osc.md lists the keys).</summary>
    public sealed class VibsynthStatus
    {
        readonly Dictionary<string, object> byKey = new Dictionary<string, object>();

        /// <summary>Every pair, in the server's order, e.g. ("version", "0.9.0"), ("channels", 2), ..., ("ch1.intensity", 0.5f).</summary>
        public ReadOnlyCollection<KeyValuePair<string, object>> Pairs { get; private set; }

        internal VibsynthStatus(OscMessage reply)
        {
            var pairs = new List<KeyValuePair<string, object>>();
            for (int i = 0; i + 1 < reply.Count; i += 2)
            {
                var pair = new KeyValuePair<string, object>(reply.GetString(i), reply.Arguments[i + 1]);
                pairs.Add(pair);
                byKey[pair.Key] = pair.Value;
            }
            Pairs = new ReadOnlyCollection<KeyValuePair<string, object>>(pairs);
        }

        /// <summary>The value of a key (int, float or string); KeyNotFoundException when absent.</summary>
        public object this[string key]
        {
            get
            {
                object value;
                if (!byKey.TryGetValue(key, out value)) throw new KeyNotFoundException("the status has no key \"" + key + "\"");
                return value;
            }
        }

        /// <summary>Is this key in the status?</summary>
        public bool ContainsKey(string key) { return byKey.ContainsKey(key); }

        /// <summary>The value of a key, false when absent.</summary>
        public bool TryGetValue(string key, out object value) { return byKey.TryGetValue(key, out value); }

        /// <summary>A numeric value as a double (-1 means the engine does not report it).</summary>
        public double GetNumber(string key) { return Convert.ToDouble(this[key], CultureInfo.InvariantCulture); }

        /// <summary>A string value.</summary>
        public string GetString(string key) { return Convert.ToString(this[key], CultureInfo.InvariantCulture); }

        /// <summary>The server's version.</summary>
        public string Version { get { return GetString("version"); } }

        /// <summary>The number of channels (actuators) the server renders.</summary>
        public int Channels { get { return (int)GetNumber("channels"); } }
    }

    /// <summary>Arguments of <see cref="VibsynthClient.ErrorReceived"/>.</summary>
    public sealed class VibsynthErrorEventArgs : EventArgs
    {
        public VibsynthError Error { get; private set; }
        internal VibsynthErrorEventArgs(VibsynthError error) { Error = error; }
    }

    /// <summary>Arguments of <see cref="VibsynthClient.MessageReceived"/>.</summary>
    public sealed class OscMessageEventArgs : EventArgs
    {
        public OscMessage Message { get; private set; }
        public OscTimeTag TimeTag { get; private set; }
        internal OscMessageEventArgs(OscReceived received) { Message = received.Message; TimeTag = received.TimeTag; }
    }

    // ================================================================== commands (client and bundle)

    /// <summary>
    /// The commands shared by <see cref="VibsynthClient"/> (sent at once) and <see cref="VibsynthBundle"/>
    /// (collected, sent together, optionally at a time). Every argument is checked before anything is sent
    /// (ArgumentException); the server checks again against its configuration and answers refusals with an
    /// error reply (see <see cref="VibsynthClient.Sync"/> and <see cref="VibsynthClient.ErrorReceived"/>).
    /// </summary>
    /// <remarks>
    /// Channels and sources count from 1, as in the server's addresses. Methods without a channel act on
    /// every channel.
    /// </remarks>
    public abstract class VibsynthCommands
    {
        /// <summary>Channels the server can have at most (<c>audio.channels</c>).</summary>
        public const int MaxChannels = 64;
        /// <summary>Spatial sources the server has (<c>/vibsynth/source/1..16</c>).</summary>
        public const int MaxSources = 16;
        /// <summary>Widest balance any server configuration accepts (<c>knobs.balance_min/max</c> are within +-10;
        /// the default live range is -3.5..3.5, and the server refuses values outside its own range).</summary>
        public const float BalanceLimit = 10f;
        /// <summary>Longest glide the server accepts, in ms.</summary>
        public const float MaxGlideMs = 10000f;
        /// <summary>Source coordinates and radii are within this many metres (the server's limit, like its layouts').</summary>
        public const float PositionLimit = 10f;
        /// <summary>Largest clip gain the server accepts.</summary>
        public const float MaxClipGain = 4f;
        /// <summary>Slowest clip playback rate the server accepts.</summary>
        public const float MinClipRate = 0.05f;
        /// <summary>Fastest clip playback rate the server accepts.</summary>
        public const float MaxClipRate = 20f;
        /// <summary>Most loop passes one play may ask for (0 = until stopped).</summary>
        public const int MaxClipLoops = 10000;
        /// <summary>Longest clip name the server accepts, in characters.</summary>
        public const int MaxClipName = 128;
        /// <summary>Longest preset name sent, in UTF-8 bytes.</summary>
        public const int MaxNameBytes = 1024;

        internal VibsynthCommands() { }

        /// <summary>The server's address prefix, e.g. <c>/vibsynth</c>.</summary>
        public abstract string Prefix { get; }

        internal abstract void Emit(byte[] message);

        // Several messages the server must apply together (a client sends them as one immediate bundle).
        internal abstract void EmitTogether(byte[][] messages);

        // -------------------------------------------------------------- addresses and checks
        internal string ChannelAddress(int channel, string method)
        {
            return Prefix + "/ch/" + CheckChannel(channel).ToString(CultureInfo.InvariantCulture) + "/" + method;
        }

        internal string SourceAddress(int source, string method)
        {
            return Prefix + "/source/" + CheckSource(source).ToString(CultureInfo.InvariantCulture) + "/" + method;
        }

        internal static int CheckChannel(int channel)
        {
            if (channel < 1 || channel > MaxChannels)
                throw new ArgumentOutOfRangeException("channel", channel, string.Format(CultureInfo.InvariantCulture,
                    "channel {0} is outside 1..{1} (channels count from 1)", channel, MaxChannels));
            return channel;
        }

        internal static int CheckSource(int source)
        {
            if (source < 1 || source > MaxSources)
                throw new ArgumentOutOfRangeException("source", source, string.Format(CultureInfo.InvariantCulture,
                    "source {0} is outside 1..{1} (sources count from 1)", source, MaxSources));
            return source;
        }

        internal static float Check(string name, float value, float low, float high)
        {
            if (float.IsNaN(value) || float.IsInfinity(value))
                throw new ArgumentException(name + " must be a finite number, got " + value.ToString(CultureInfo.InvariantCulture), name);
            if (value < low || value > high)
                throw new ArgumentOutOfRangeException(name, value, string.Format(CultureInfo.InvariantCulture,
                    "{0} {1} is outside the allowed range [{2}, {3}]", name, value, low, high));
            return value;
        }

        internal static float Finite(string name, float value)
        {
            return Check(name, value, float.MinValue, float.MaxValue);
        }

        internal static float CheckAtLeast(string name, float value, float low)
        {
            Finite(name, value);
            if (value < low)
                throw new ArgumentOutOfRangeException(name, value, string.Format(CultureInfo.InvariantCulture,
                    "{0} must be >= {1}, got {2}", name, low, value));
            return value;
        }

        internal static float CheckPositive(string name, float value)
        {
            Finite(name, value);
            if (value <= 0f)
                throw new ArgumentOutOfRangeException(name, value, string.Format(CultureInfo.InvariantCulture,
                    "{0} must be > 0, got {1}", name, value));
            return value;
        }

        internal static float CheckRadius(float metres)
        {
            CheckPositive("radius (m)", metres);
            return Check("radius (m)", metres, 0f, PositionLimit);
        }

        internal static string CheckName(string what, string name)
        {
            if (name == null) throw new ArgumentNullException(what, what + " must not be null");
            if (name.Length == 0 || name.IndexOf('\0') >= 0)
                throw new ArgumentException(what + " must be a non-empty text without NUL characters", what);
            if (Encoding.UTF8.GetByteCount(name) > MaxNameBytes)
                throw new ArgumentException(string.Format(CultureInfo.InvariantCulture,
                    "{0} is longer than {1} bytes", what, MaxNameBytes), what);
            return name;
        }

        static string RolloffName(Rolloff law)
        {
            switch (law)
            {
                case Rolloff.Linear: return "linear";
                case Rolloff.Smooth: return "smooth";
                case Rolloff.InverseSquare: return "inverse-square";
                case Rolloff.Phantom: return "phantom";
                default: throw new ArgumentOutOfRangeException("law", law, "unknown roll-off law");
            }
        }

        /// <summary>The server's name of a roll-off law (<c>linear</c>, <c>smooth</c>, <c>inverse-square</c>, <c>phantom</c>).</summary>
        public static string NameOf(Rolloff law) { return RolloffName(law); }

        /// <summary>The roll-off law of a server name; ArgumentException for an unknown one.</summary>
        public static Rolloff ParseRolloff(string name)
        {
            foreach (Rolloff law in new[] { Rolloff.Linear, Rolloff.Smooth, Rolloff.InverseSquare, Rolloff.Phantom })
                if (RolloffName(law) == name) return law;
            throw new ArgumentException("unknown roll-off law \"" + name + "\" (linear, smooth, inverse-square or phantom)", "name");
        }

        void Send(string address, string tags, params object[] args)
        {
            Emit(Osc.EncodeMessage(address, tags, args));
        }

        // -------------------------------------------------------------- channel knobs
        /// <summary>Set every channel's intensity, 0..1 (with the channel's glide).</summary>
        public void SetIntensity(float intensity)
        {
            Send(Prefix + "/intensity", "f", Check("intensity", intensity, 0f, 1f));
        }

        /// <summary>Set one channel's intensity, 0..1.</summary>
        public void SetIntensity(int channel, float intensity)
        {
            Send(ChannelAddress(channel, "intensity"), "f", Check("intensity", intensity, 0f, 1f));
        }

        /// <summary>Set every channel's balance (finite; the server accepts its live range, -3.5..3.5 by default).</summary>
        public void SetBalance(float balance)
        {
            Send(Prefix + "/balance", "f", Check("balance", balance, -BalanceLimit, BalanceLimit));
        }

        /// <summary>Set one channel's balance.</summary>
        public void SetBalance(int channel, float balance)
        {
            Send(ChannelAddress(channel, "balance"), "f", Check("balance", balance, -BalanceLimit, BalanceLimit));
        }

        /// <summary>Set intensity and balance of every channel at once (the server checks both before changing either).</summary>
        public void SetTexture(float intensity, float balance)
        {
            Send(Prefix + "/texture", "ff", Check("intensity", intensity, 0f, 1f), Check("balance", balance, -BalanceLimit, BalanceLimit));
        }

        /// <summary>Set intensity and balance of one channel at once.</summary>
        public void SetTexture(int channel, float intensity, float balance)
        {
            Send(ChannelAddress(channel, "texture"), "ff", Check("intensity", intensity, 0f, 1f), Check("balance", balance, -BalanceLimit, BalanceLimit));
        }

        /// <summary>Set the glide (smoothing) of every channel's later knob moves, in ms (0 = jump, at most 10 000).</summary>
        public void SetGlide(float milliseconds)
        {
            Send(Prefix + "/glide", "f", Check("glide (ms)", milliseconds, 0f, MaxGlideMs));
        }

        /// <summary>Set one channel's glide, in ms.</summary>
        public void SetGlide(int channel, float milliseconds)
        {
            Send(ChannelAddress(channel, "glide"), "f", Check("glide (ms)", milliseconds, 0f, MaxGlideMs));
        }

        /// <summary>Set every channel's intensity from a scanning speed in mm/s (>= 0) through the server's speed curve.</summary>
        public void SetSpeed(float millimetresPerSecond)
        {
            Send(Prefix + "/speed", "f", CheckAtLeast("speed (mm/s)", millimetresPerSecond, 0f));
        }

        /// <summary>Set one channel's intensity from a scanning speed in mm/s.</summary>
        public void SetSpeed(int channel, float millimetresPerSecond)
        {
            Send(ChannelAddress(channel, "speed"), "f", CheckAtLeast("speed (mm/s)", millimetresPerSecond, 0f));
        }

        /// <summary>Mute every channel with a short fade (true) or unmute (false); knob values are kept.</summary>
        public void Mute(bool on = true)
        {
            Send(Prefix + "/mute", "i", on ? 1 : 0);
        }

        /// <summary>Mute (true) or unmute (false) one channel.</summary>
        public void Mute(int channel, bool on = true)
        {
            Send(ChannelAddress(channel, "mute"), "i", on ? 1 : 0);
        }

        /// <summary>Unmute every channel.</summary>
        public void Unmute() { Mute(false); }

        /// <summary>Unmute one channel.</summary>
        public void Unmute(int channel) { Mute(channel, false); }

        /// <summary>Silence everything now: intensity 0, scheduled moves dropped (always immediate, even in a timetagged bundle).</summary>
        public void Panic()
        {
            Send(Prefix + "/panic", "");
        }

        /// <summary>Glide every channel to a preset's knobs (with the preset's glide); the server refuses an unknown name.</summary>
        public void LoadPreset(string name)
        {
            Send(Prefix + "/preset", "s", CheckName("preset name", name));
        }

        /// <summary>Glide one channel to a preset's knobs.</summary>
        public void LoadPreset(int channel, string name)
        {
            Send(ChannelAddress(channel, "preset"), "s", CheckName("preset name", name));
        }

        // -------------------------------------------------------------- spatial sources
        /// <summary>Move a source (1..16) to (x, y) in the layout's frame, in metres (<c>pos f f</c>: z = 0).</summary>
        public void SourcePosition(int source, float x, float y)
        {
            Send(SourceAddress(source, "pos"), "ff", Check("x (m)", x, -PositionLimit, PositionLimit),
                Check("y (m)", y, -PositionLimit, PositionLimit));
        }

        /// <summary>Move a source (1..16) to (x, y, z) in the layout's frame, in metres (it glides like a knob).</summary>
        public void SourcePosition(int source, float x, float y, float z)
        {
            Send(SourceAddress(source, "pos"), "fff", Check("x (m)", x, -PositionLimit, PositionLimit),
                Check("y (m)", y, -PositionLimit, PositionLimit), Check("z (m)", z, -PositionLimit, PositionLimit));
        }

        /// <summary>Set a source's intensity (0..1) and balance at once.</summary>
        public void SourceTexture(int source, float intensity, float balance)
        {
            Send(SourceAddress(source, "texture"), "ff", Check("intensity", intensity, 0f, 1f),
                Check("balance", balance, -BalanceLimit, BalanceLimit));
        }

        /// <summary>Set a source's intensity, 0..1.</summary>
        public void SourceIntensity(int source, float intensity)
        {
            Send(SourceAddress(source, "intensity"), "f", Check("intensity", intensity, 0f, 1f));
        }

        /// <summary>Set a source's balance.</summary>
        public void SourceBalance(int source, float balance)
        {
            Send(SourceAddress(source, "balance"), "f", Check("balance", balance, -BalanceLimit, BalanceLimit));
        }

        /// <summary>Give a source a preset's knobs.</summary>
        public void SourcePreset(int source, string name)
        {
            Send(SourceAddress(source, "preset"), "s", CheckName("preset name", name));
        }

        /// <summary>Set a source's radius in metres (> 0, at most 10; the server's <c>sources.radius</c> bounds it).</summary>
        public void SourceRadius(int source, float metres)
        {
            Send(SourceAddress(source, "radius"), "f", CheckRadius(metres));
        }

        /// <summary>Set a source's roll-off law.</summary>
        public void SourceRolloff(int source, Rolloff law)
        {
            Send(SourceAddress(source, "rolloff"), "s", RolloffName(law));
        }

        /// <summary>Turn a source on (true) or off (false).</summary>
        public void SourceOn(int source, bool on = true)
        {
            Send(SourceAddress(source, "on"), "i", on ? 1 : 0);
        }

        /// <summary>
        /// Let a source's intensity follow its speed (true: through the server's speed curve, from its positions
        /// over <c>sources.speed_window_ms</c>; at rest it is silent) or use its own intensity (false).
        /// </summary>
        public void SourceSpeed(int source, bool fromSpeed = true)
        {
            Send(SourceAddress(source, "speed"), "i", fromSpeed ? 1 : 0);
        }

        /// <summary>Place a source, give it its knobs and turn it on or off, applied together (one bundle).</summary>
        public void SetSource(int source, float x, float y, float z, float intensity, float balance, bool on = true)
        {
            EmitTogether(SourceMessages(source, x, y, z, intensity, balance, null, null, on));
        }

        /// <summary>Place a source with its knobs, radius (m) and roll-off law, and turn it on or off, applied together.</summary>
        public void SetSource(int source, float x, float y, float z, float intensity, float balance, float radius, Rolloff rolloff, bool on = true)
        {
            EmitTogether(SourceMessages(source, x, y, z, intensity, balance, radius, rolloff, on));
        }

        byte[][] SourceMessages(int source, float x, float y, float z, float intensity, float balance, float? radius, Rolloff? rolloff, bool on)
        {
            var messages = new List<byte[]>();
            messages.Add(Osc.EncodeMessage(SourceAddress(source, "pos"), "fff", new object[] {
                Check("x (m)", x, -PositionLimit, PositionLimit), Check("y (m)", y, -PositionLimit, PositionLimit),
                Check("z (m)", z, -PositionLimit, PositionLimit) }));
            messages.Add(Osc.EncodeMessage(SourceAddress(source, "texture"), "ff", new object[] {
                Check("intensity", intensity, 0f, 1f), Check("balance", balance, -BalanceLimit, BalanceLimit) }));
            if (radius.HasValue)
                messages.Add(Osc.EncodeMessage(SourceAddress(source, "radius"), "f", new object[] { CheckRadius(radius.Value) }));
            if (rolloff.HasValue)
                messages.Add(Osc.EncodeMessage(SourceAddress(source, "rolloff"), "s", new object[] { RolloffName(rolloff.Value) }));
            messages.Add(Osc.EncodeMessage(SourceAddress(source, "on"), "i", new object[] { on ? 1 : 0 }));
            return messages.ToArray();
        }

        // -------------------------------------------------------------- clips
        /// <summary>Play a haptic clip on one channel: it drives the channel's knobs until it ends, then the channel glides back.</summary>
        /// <param name="channel">1-based channel.</param>
        /// <param name="name">Clip name (<c>vibsynth clip list</c>); the server refuses an unknown one.</param>
        /// <param name="gain">Intensity scale, 0..4 (the result is clamped to 1); null = 1.</param>
        /// <param name="rate">Playback speed, 0.05..20 (2 = twice as fast); null = 1.</param>
        /// <param name="loops">Passes through the clip's loop, 1..10 000, or 0 = until stopped; null = 1.</param>
        /// <remarks>Only the arguments given are sent (a later one needs the earlier: 1 is sent for those missing).</remarks>
        public void PlayClip(int channel, string name, float? gain = null, float? rate = null, int? loops = null)
        {
            Emit(ClipMessage(ChannelAddress(channel, "play"), name, gain, rate, loops));
        }

        /// <summary>Play a haptic clip on every channel (see <see cref="PlayClip"/>).</summary>
        public void PlayClipAll(string name, float? gain = null, float? rate = null, int? loops = null)
        {
            Emit(ClipMessage(Prefix + "/play", name, gain, rate, loops));
        }

        /// <summary>Stop the clip on one channel; it glides back to its knob state over <paramref name="releaseMs"/> (null = the server's default).</summary>
        public void StopClip(int channel, float? releaseMs = null)
        {
            Emit(StopMessage(ChannelAddress(channel, "stop"), releaseMs));
        }

        /// <summary>Stop the clips on every channel.</summary>
        public void StopClipAll(float? releaseMs = null)
        {
            Emit(StopMessage(Prefix + "/stop", releaseMs));
        }

        static byte[] ClipMessage(string address, string name, float? gain, float? rate, int? loops)
        {
            var args = new List<object>();
            var tags = new StringBuilder("s");
            args.Add(CheckName("clip name", name));
            if (name.Length > MaxClipName)
                throw new ArgumentException(string.Format(CultureInfo.InvariantCulture,
                    "clip name is longer than {0} characters", MaxClipName), "name");
            if (gain.HasValue || rate.HasValue || loops.HasValue)
            {
                args.Add(Check("gain", gain ?? 1f, 0f, MaxClipGain));
                tags.Append('f');
            }
            if (rate.HasValue || loops.HasValue)
            {
                args.Add(Check("rate", rate ?? 1f, MinClipRate, MaxClipRate));
                tags.Append('f');
            }
            if (loops.HasValue)
            {
                if (loops.Value < 0 || loops.Value > MaxClipLoops)
                    throw new ArgumentOutOfRangeException("loops", loops.Value, string.Format(CultureInfo.InvariantCulture,
                        "loops {0} is outside the allowed range [0, {1}] (0 = until stopped)", loops.Value, MaxClipLoops));
                args.Add(loops.Value);
                tags.Append('i');
            }
            return Osc.EncodeMessage(address, tags.ToString(), args);
        }

        static byte[] StopMessage(string address, float? releaseMs)
        {
            if (!releaseMs.HasValue) return Osc.EncodeMessage(address, "", new object[0]);
            return Osc.EncodeMessage(address, "f", new object[] { Check("release (ms)", releaseMs.Value, 0f, MaxGlideMs) });
        }

        // -------------------------------------------------------------- live Follow (serve --follow)
        // The server holds the ranges (the typed follow: settings) and refuses a value outside them;
        // Sync() raises the refusal. Here only what no server takes is refused (NaN, an empty name).

        /// <summary>Every followed channel follows the input (true) or plays its knobs again (false).</summary>
        public void SetFollow(bool on = true)
        {
            Send(Prefix + "/ch/*/follow", "i", on ? 1 : 0);
        }

        /// <summary>One channel follows the input (true) or plays its knobs again (false); the server refuses a channel no route follows into.</summary>
        public void SetFollow(int channel, bool on = true)
        {
            Send(ChannelAddress(channel, "follow"), "i", on ? 1 : 0);
        }

        /// <summary>Follow's gain in dB, added to the tracked level (the server checks <c>follow.gain_db</c>'s range, −60..60).</summary>
        public void SetFollowGain(float db)
        {
            Send(Prefix + "/follow/gain", "f", Finite("follow gain (dB)", db));
        }

        /// <summary>Follow's gate in dB: below this input level the output is silent (<c>follow.gate_db</c>'s range, −200..0).</summary>
        public void SetFollowGate(float db)
        {
            Send(Prefix + "/follow/gate", "f", Finite("follow gate (dB)", db));
        }

        /// <summary>Follow's input range in dB, spread over the intensity knob in audio mode (<c>follow.range_db</c>'s range, 6..120).</summary>
        public void SetFollowRange(float db)
        {
            Send(Prefix + "/follow/range", "f", Finite("follow range (dB)", db));
        }

        /// <summary>What shakes in audio mode: <c>all</c>, <c>effects</c>, <c>bass</c> or <c>beat</c> (the server refuses another name).</summary>
        public void SetFollowFocus(string focus)
        {
            Send(Prefix + "/follow/focus", "s", CheckName("follow focus", focus));
        }
    }

    // ================================================================== bundles

    /// <summary>
    /// Commands collected into one OSC bundle, sent by <see cref="Send"/>: the server applies them together
    /// (in the same audio block), at once or at the bundle's time, to the exact sample.
    /// </summary>
    /// <remarks>
    /// Made by <see cref="VibsynthClient.Bundle"/> (immediately) and <see cref="VibsynthClient.At(double)"/>
    /// (a time). Only knob, glide, mute, preset, source and clip messages are scheduled by the server;
    /// <c>Panic</c> and queries act at once. The server refuses times more than <c>osc.schedule_horizon_s</c>
    /// (10 s) ahead; a time in the past applies at once. Not thread-safe: fill a bundle from one thread.
    /// </remarks>
    public sealed class VibsynthBundle : VibsynthCommands
    {
        readonly VibsynthClient client;
        readonly List<byte[]> elements = new List<byte[]>();
        int size = 16;
        bool sent;

        internal VibsynthBundle(VibsynthClient client, OscTimeTag timeTag)
        {
            this.client = client;
            TimeTag = timeTag;
        }

        /// <summary>When the server applies the bundle (<see cref="OscTimeTag.Immediately"/> or a wall-clock time).</summary>
        public OscTimeTag TimeTag { get; private set; }

        /// <inheritdoc/>
        public override string Prefix { get { return client.Prefix; } }

        /// <summary>How many messages the bundle holds.</summary>
        public int Count { get { return elements.Count; } }

        /// <summary>The bundle's size in bytes when encoded.</summary>
        public int Size { get { return size; } }

        internal override void Emit(byte[] message)
        {
            if (sent) throw new InvalidOperationException("this bundle was already sent; make a new one with client.Bundle() or client.At(...)");
            if (size + 4 + message.Length > Osc.MaxDatagram)
                throw new InvalidOperationException(string.Format(CultureInfo.InvariantCulture,
                    "the bundle would exceed a UDP datagram ({0} bytes); send it and start another", Osc.MaxDatagram));
            elements.Add(message);
            size += 4 + message.Length;
        }

        internal override void EmitTogether(byte[][] messages)
        {
            int more = 0;
            foreach (byte[] message in messages) more += 4 + message.Length;
            if (size + more > Osc.MaxDatagram)
                throw new InvalidOperationException("the bundle would exceed a UDP datagram; send it and start another");
            foreach (byte[] message in messages) Emit(message);
        }

        /// <summary>Add any message (address and values; type tags inferred, see <see cref="Osc.TypeTagOf"/>).</summary>
        public void Add(string address, params object[] arguments)
        {
            Emit(Osc.EncodeMessage(address, arguments));
        }

        /// <summary>Add a message.</summary>
        public void Add(OscMessage message)
        {
            Emit(Osc.Encode(message));
        }

        /// <summary>The bundle as one OSC packet.</summary>
        public byte[] Encode()
        {
            return Osc.EncodeBundle(TimeTag, elements);
        }

        /// <summary>Send the bundle (once).</summary>
        /// <exception cref="InvalidOperationException">It was already sent.</exception>
        public void Send()
        {
            if (sent) throw new InvalidOperationException("this bundle was already sent");
            byte[] packet = Encode();
            sent = true;
            client.SendPacket(packet);
        }
    }

    // ================================================================== the client

    /// <summary>
    /// Talks to a running <c>vibsynth serve</c> over OSC/UDP: setters send at once, queries await their reply.
    /// </summary>
    /// <remarks>
    /// One UDP socket per client; the server replies to it. A background thread receives and matches replies to
    /// the waiting queries (by address and shape, in order). Every method is thread-safe. Refusals of setters
    /// (values outside the server's configured range, unknown presets, channels the server does not have) arrive
    /// as error replies: <see cref="Sync"/> raises them, <see cref="ErrorReceived"/> reports each as it arrives,
    /// <see cref="TakeErrors"/> returns those not reported yet.
    /// Replies are accepted only from the server's address and port.
    /// </remarks>
    public sealed class VibsynthClient : VibsynthCommands, IDisposable
    {
        /// <summary>The server's default port (<c>osc.port</c>).</summary>
        public const int DefaultPort = 9570;
        /// <summary>The server's default address prefix (<c>osc.prefix</c>).</summary>
        public const string DefaultPrefix = "/vibsynth";
        /// <summary>Refusals kept for <see cref="Sync"/> / <see cref="TakeErrors"/> (older ones are dropped).</summary>
        public const int MaxPendingErrors = 256;

        readonly string host;
        readonly int port;
        readonly string prefix;
        readonly IPEndPoint server;
        readonly Socket socket;
        readonly Thread receiver;
        readonly object sendGate = new object();
        readonly object pendingGate = new object();
        readonly LinkedList<PendingRequest> pending = new LinkedList<PendingRequest>();
        readonly Queue<VibsynthError> errors = new Queue<VibsynthError>();
        long timeoutTicks = TimeSpan.FromSeconds(1).Ticks;
        int nextId;
        volatile bool disposed;

        long sentCount, receivedCount, malformedCount, ignoredCount, errorCount, foreignCount, handlerFailureCount;

        /// <summary>Connect to a server (nothing is sent until the first command).</summary>
        /// <param name="host">Host name or IP address of the server (IPv4 preferred when a name has both).</param>
        /// <param name="port">The server's UDP port (<c>osc.port</c>).</param>
        /// <param name="prefix">The server's address prefix (<c>osc.prefix</c>); "" for none.</param>
        /// <param name="localPort">Local UDP port to send from and receive on (0 = any free port).</param>
        /// <exception cref="ArgumentException">Bad port, prefix, or a host name that does not resolve.</exception>
        /// <exception cref="SocketException">The local port cannot be bound.</exception>
        public VibsynthClient(string host = "127.0.0.1", int port = DefaultPort, string prefix = DefaultPrefix, int localPort = 0)
        {
            if (host == null) throw new ArgumentNullException("host");
            if (port < 1 || port > 65535) throw new ArgumentOutOfRangeException("port", port, "port must be in 1..65535");
            if (localPort < 0 || localPort > 65535) throw new ArgumentOutOfRangeException("localPort", localPort, "local port must be in 0..65535");
            this.host = host;
            this.port = port;
            this.prefix = CheckPrefix(prefix);
            server = new IPEndPoint(Resolve(host), port);
            socket = new Socket(server.AddressFamily, SocketType.Dgram, ProtocolType.Udp);
            try
            {
                IgnoreConnectionResets(socket);
                socket.Bind(new IPEndPoint(server.AddressFamily == AddressFamily.InterNetworkV6 ? IPAddress.IPv6Any : IPAddress.Any, localPort));
                socket.ReceiveBufferSize = 1 << 20;
            }
            catch
            {
                socket.Close();
                throw;
            }
            nextId = new Random().Next(1, 1 << 30);
            receiver = new Thread(ReceiveLoop);
            receiver.IsBackground = true;
            receiver.Name = "vibsynth-client-receive";
            receiver.Start();
        }

        static string CheckPrefix(string prefix)
        {
            if (prefix == null) throw new ArgumentNullException("prefix");
            prefix = prefix.TrimEnd('/');
            if (prefix.Length == 0) return prefix;
            if (prefix[0] != '/' || prefix.IndexOfAny(" \t\r\n*?[]{}#,\0".ToCharArray()) >= 0)
                throw new ArgumentException("prefix \"" + prefix + "\" must start with '/' and contain no spaces or OSC pattern characters", "prefix");
            return prefix;
        }

        static IPAddress Resolve(string host)
        {
            IPAddress address;
            if (IPAddress.TryParse(host, out address)) return address;
            IPAddress[] found;
            try
            {
                found = Dns.GetHostAddresses(host);
            }
            catch (SocketException e)
            {
                throw new ArgumentException("cannot resolve host \"" + host + "\": " + e.Message, "host");
            }
            // IPv4 first: "localhost" may list ::1 first while the server listens on 127.0.0.1
            foreach (IPAddress candidate in found)
                if (candidate.AddressFamily == AddressFamily.InterNetwork) return candidate;
            foreach (IPAddress candidate in found)
                if (candidate.AddressFamily == AddressFamily.InterNetworkV6) return candidate;
            throw new ArgumentException("host \"" + host + "\" has no IP address", "host");
        }

        // Windows reports an ICMP "port unreachable" of an earlier send as an error of the next receive
        // (WSAECONNRESET); switch that off so a server that is not running yet cannot stop the receive loop.
        static void IgnoreConnectionResets(Socket socket)
        {
            if (Environment.OSVersion.Platform != PlatformID.Win32NT) return;
            const int SioUdpConnReset = -1744830452; // _WSAIOW(IOC_VENDOR, 12)
            try
            {
                socket.IOControl(SioUdpConnReset, new byte[] { 0, 0, 0, 0 }, null);
            }
            catch (Exception)
            {
                // not supported on this runtime: the receive loop also survives the error
            }
        }

        // -------------------------------------------------------------- properties
        /// <summary>The server's host, as given.</summary>
        public string Host { get { return host; } }
        /// <summary>The server's UDP port.</summary>
        public int Port { get { return port; } }
        /// <inheritdoc/>
        public override string Prefix { get { return prefix; } }
        /// <summary>The local endpoint replies come back to.</summary>
        public IPEndPoint LocalEndPoint { get { return (IPEndPoint)socket.LocalEndPoint; } }
        /// <summary>True after <see cref="Dispose"/>.</summary>
        public bool IsDisposed { get { return disposed; } }

        /// <summary>How long queries wait for their reply when no timeout is given (default 1 s; 1 ms..1 h).</summary>
        public TimeSpan Timeout
        {
            get { return TimeSpan.FromTicks(Interlocked.Read(ref timeoutTicks)); }
            set { Interlocked.Exchange(ref timeoutTicks, CheckTimeout(value).Ticks); }
        }

        static TimeSpan CheckTimeout(TimeSpan timeout)
        {
            if (timeout < TimeSpan.FromMilliseconds(1) || timeout > TimeSpan.FromHours(1))
                throw new ArgumentOutOfRangeException("timeout", timeout, "a timeout is between 1 ms and 1 hour");
            return timeout;
        }

        /// <summary>Packets sent.</summary>
        public long Sent { get { return Interlocked.Read(ref sentCount); } }
        /// <summary>Datagrams received from the server.</summary>
        public long Received { get { return Interlocked.Read(ref receivedCount); } }
        /// <summary>Datagrams that were not valid OSC, or replies of an unexpected shape (ignored).</summary>
        public long Malformed { get { return Interlocked.Read(ref malformedCount); } }
        /// <summary>Valid messages no query was waiting for (e.g. a reply that came after its timeout).</summary>
        public long Ignored { get { return Interlocked.Read(ref ignoredCount); } }
        /// <summary>Error replies received.</summary>
        public long ErrorReplies { get { return Interlocked.Read(ref errorCount); } }
        /// <summary>Datagrams from anyone but the server (dropped).</summary>
        public long Foreign { get { return Interlocked.Read(ref foreignCount); } }
        /// <summary>Exceptions thrown by <see cref="ErrorReceived"/> / <see cref="MessageReceived"/> handlers (caught, counted).</summary>
        public long HandlerFailures { get { return Interlocked.Read(ref handlerFailureCount); } }

        /// <summary>An error reply no query was waiting for (a refused setter). Raised on the receive thread.</summary>
        public event EventHandler<VibsynthErrorEventArgs> ErrorReceived;

        /// <summary>A message no query was waiting for (e.g. <c>/notify</c> pushes). Raised on the receive thread.</summary>
        public event EventHandler<OscMessageEventArgs> MessageReceived;

        // -------------------------------------------------------------- sending
        /// <summary>Send one encoded OSC packet (message or bundle).</summary>
        /// <exception cref="ArgumentException">Empty, or larger than a UDP datagram.</exception>
        /// <exception cref="ObjectDisposedException">The client was disposed.</exception>
        /// <exception cref="SocketException">The operating system refused to send.</exception>
        public void SendPacket(byte[] packet)
        {
            CheckPacket(packet);
            lock (sendGate)
            {
                Transmit(packet);
            }
        }

        static void CheckPacket(byte[] packet)
        {
            if (packet == null) throw new ArgumentNullException("packet");
            if (packet.Length == 0 || packet.Length > Osc.MaxDatagram)
                throw new ArgumentException(string.Format(CultureInfo.InvariantCulture,
                    "an OSC packet over UDP has 1..{0} bytes, got {1}", Osc.MaxDatagram, packet.Length), "packet");
        }

        void Transmit(byte[] packet)
        {
            if (disposed) throw new ObjectDisposedException("VibsynthClient");
            socket.SendTo(packet, server);
            Interlocked.Increment(ref sentCount);
        }

        /// <summary>Send any message, e.g. <c>Send("/vibsynth/ch/*/balance", 1f)</c> (type tags inferred from the values).</summary>
        public void Send(string address, params object[] arguments)
        {
            SendPacket(Osc.EncodeMessage(address, arguments));
        }

        internal override void Emit(byte[] message) { SendPacket(message); }

        internal override void EmitTogether(byte[][] messages)
        {
            SendPacket(Osc.EncodeBundle(OscTimeTag.Immediately, messages));
        }

        /// <summary>A bundle the server applies at once, all its commands in the same audio block.</summary>
        public VibsynthBundle Bundle()
        {
            return new VibsynthBundle(this, OscTimeTag.Immediately);
        }

        /// <summary>A bundle the server applies <paramref name="secondsFromNow"/> from now (taken when At is called), to the sample.</summary>
        /// <exception cref="ArgumentException">Not finite, negative, or beyond an hour (the server's own horizon is 10 s by default).</exception>
        public VibsynthBundle At(double secondsFromNow)
        {
            if (double.IsNaN(secondsFromNow) || double.IsInfinity(secondsFromNow) || secondsFromNow < 0 || secondsFromNow > 3600)
                throw new ArgumentOutOfRangeException("secondsFromNow", secondsFromNow, "a bundle time from now is 0..3600 s");
            return new VibsynthBundle(this, OscTimeTag.FromNow(secondsFromNow));
        }

        /// <summary>A bundle the server applies at a wall-clock time (server and client clocks must agree: NTP).</summary>
        public VibsynthBundle At(DateTime time)
        {
            return new VibsynthBundle(this, OscTimeTag.FromDateTime(time));
        }

        /// <summary>A bundle for a given time tag.</summary>
        public VibsynthBundle At(OscTimeTag timeTag)
        {
            return new VibsynthBundle(this, timeTag);
        }

        // -------------------------------------------------------------- requests
        abstract class PendingRequest
        {
            public string RequestAddress;
            public LinkedListNode<PendingRequest> Node;
            public abstract bool Matches(OscMessage reply);
            public abstract void Complete(OscMessage reply);
            public abstract void Fail(Exception error);
        }

        sealed class PendingRequest<T> : PendingRequest
        {
            public readonly TaskCompletionSource<T> Source = new TaskCompletionSource<T>(TaskCreationOptions.RunContinuationsAsynchronously);
            public Func<OscMessage, bool> Match;
            public Func<OscMessage, T> Convert;
            public CancellationTokenSource Timer;

            public override bool Matches(OscMessage reply) { return Match(reply); }

            public override void Complete(OscMessage reply)
            {
                Timer.Dispose();
                T value;
                try
                {
                    value = Convert(reply);
                }
                catch (Exception e)
                {
                    Source.TrySetException(e);
                    return;
                }
                Source.TrySetResult(value);
            }

            public override void Fail(Exception error)
            {
                Timer.Dispose();
                Source.TrySetException(error);
            }
        }

        /// <summary>
        /// Send a message and await the first reply <paramref name="match"/> accepts; an error reply about
        /// <paramref name="address"/> fails it with <see cref="VibsynthServerException"/>.
        /// </summary>
        /// <param name="address">The request's address.</param>
        /// <param name="typeTags">Its type tags.</param>
        /// <param name="arguments">Its values.</param>
        /// <param name="match">Which reply answers it (called on the receive thread; keep it quick).</param>
        /// <param name="timeout">How long to wait (null = <see cref="Timeout"/>).</param>
        /// <returns>The reply.</returns>
        public Task<OscMessage> RequestAsync(string address, string typeTags, IList<object> arguments, Func<OscMessage, bool> match, TimeSpan? timeout = null)
        {
            if (match == null) throw new ArgumentNullException("match");
            return Request(address, Osc.EncodeMessage(address, typeTags, arguments), match, m => m, timeout);
        }

        Task<T> Request<T>(string address, byte[] packet, Func<OscMessage, bool> match, Func<OscMessage, T> convert, TimeSpan? timeout)
        {
            TimeSpan wait = timeout.HasValue ? CheckTimeout(timeout.Value) : Timeout;
            CheckPacket(packet);
            var request = new PendingRequest<T>();
            request.RequestAddress = address;
            request.Match = match;
            request.Convert = convert;
            // the timeout is armed before the request can be answered (Complete disposes the timer)
            request.Timer = new CancellationTokenSource();
            request.Timer.Token.Register(delegate
            {
                if (Remove(request))
                    request.Source.TrySetException(new VibsynthTimeoutException(host, port, address, wait));
            });
            lock (sendGate) // register and send in one step: requests to one address are answered in this order
            {
                if (disposed)
                {
                    request.Timer.Dispose();
                    throw new ObjectDisposedException("VibsynthClient");
                }
                lock (pendingGate)
                {
                    request.Node = pending.AddLast(request);
                }
                try
                {
                    Transmit(packet);
                }
                catch
                {
                    Remove(request);
                    request.Timer.Dispose();
                    throw;
                }
            }
            try
            {
                request.Timer.CancelAfter(wait);
            }
            catch (ObjectDisposedException)
            {
                // answered already: Complete disposed the timer
            }
            return request.Source.Task;
        }

        bool Remove(PendingRequest request)
        {
            lock (pendingGate)
            {
                if (request.Node.List == null) return false;
                pending.Remove(request.Node);
                return true;
            }
        }

        // Blocks until the task finishes; rethrows its exception as is (not wrapped in an AggregateException).
        static T Wait<T>(Task<T> task)
        {
            return task.GetAwaiter().GetResult();
        }

        static bool IsNumber1(OscMessage m) { return m.Count == 1 && m.IsNumber(0); }

        static bool IsFlag(OscMessage m) { return m.Count == 1 && (m.TypeTags == "i" || m.TypeTags == "T" || m.TypeTags == "F"); }

        Task<T> Get<T>(int channel, string what, Func<OscMessage, bool> shape, Func<OscMessage, T> convert, TimeSpan? timeout)
        {
            return Query(ChannelAddress(channel, ""), what, shape, convert, timeout);
        }

        Task<T> GetSource<T>(int source, string what, Func<OscMessage, bool> shape, Func<OscMessage, T> convert, TimeSpan? timeout)
        {
            return Query(SourceAddress(source, ""), what, shape, convert, timeout);
        }

        // `{base}get s what`, answered in setter form at `{base}{what}` (base ends in '/')
        Task<T> Query<T>(string base_, string what, Func<OscMessage, bool> shape, Func<OscMessage, T> convert, TimeSpan? timeout)
        {
            string want = base_ + what;
            string address = base_ + "get";
            return Request(address, Osc.EncodeMessage(address, "s", new object[] { what }),
                reply => reply.Address == want && Shaped(reply, shape), convert, timeout);
        }

        // A reply at the expected address but of another shape is counted as malformed and not taken.
        bool Shaped(OscMessage reply, Func<OscMessage, bool> shape)
        {
            if (shape(reply)) return true;
            Interlocked.Increment(ref malformedCount);
            return false;
        }

        // -------------------------------------------------------------- channel queries
        /// <summary>A channel's intensity target (what was last requested, scheduled moves included).</summary>
        /// <exception cref="VibsynthServerException">The server refused (e.g. it has no such channel).</exception>
        /// <exception cref="VibsynthTimeoutException">No answer within the timeout.</exception>
        public Task<float> GetIntensityAsync(int channel = 1, TimeSpan? timeout = null)
        {
            return Get(channel, "intensity", IsNumber1, m => m.GetFloat(0), timeout);
        }

        /// <summary>A channel's intensity target; blocks up to the timeout (see <see cref="GetIntensityAsync"/>).</summary>
        public float GetIntensity(int channel = 1, TimeSpan? timeout = null) { return Wait(GetIntensityAsync(channel, timeout)); }

        /// <summary>A channel's balance target.</summary>
        public Task<float> GetBalanceAsync(int channel = 1, TimeSpan? timeout = null)
        {
            return Get(channel, "balance", IsNumber1, m => m.GetFloat(0), timeout);
        }

        /// <summary>A channel's balance target; blocks up to the timeout.</summary>
        public float GetBalance(int channel = 1, TimeSpan? timeout = null) { return Wait(GetBalanceAsync(channel, timeout)); }

        /// <summary>What a channel plays: intensity and balance (under a source or a clip, what they make it play).</summary>
        public Task<Texture> GetTextureAsync(int channel = 1, TimeSpan? timeout = null)
        {
            return Get(channel, "texture", m => m.Count == 2 && m.IsNumber(0) && m.IsNumber(1),
                m => new Texture(m.GetFloat(0), m.GetFloat(1)), timeout);
        }

        /// <summary>What a channel plays; blocks up to the timeout.</summary>
        public Texture GetTexture(int channel = 1, TimeSpan? timeout = null) { return Wait(GetTextureAsync(channel, timeout)); }

        /// <summary>A channel's glide in ms.</summary>
        public Task<float> GetGlideAsync(int channel = 1, TimeSpan? timeout = null)
        {
            return Get(channel, "glide", IsNumber1, m => m.GetFloat(0), timeout);
        }

        /// <summary>A channel's glide in ms; blocks up to the timeout.</summary>
        public float GetGlide(int channel = 1, TimeSpan? timeout = null) { return Wait(GetGlideAsync(channel, timeout)); }

        /// <summary>Is a channel muted?</summary>
        public Task<bool> GetMuteAsync(int channel = 1, TimeSpan? timeout = null)
        {
            return Get(channel, "mute", IsFlag, m => m.GetInt(0) != 0, timeout);
        }

        /// <summary>Is a channel muted? Blocks up to the timeout.</summary>
        public bool GetMute(int channel = 1, TimeSpan? timeout = null) { return Wait(GetMuteAsync(channel, timeout)); }

        /// <summary>The preset a channel last got, or null when none.</summary>
        public Task<string> GetPresetAsync(int channel = 1, TimeSpan? timeout = null)
        {
            return Get(channel, "preset", m => m.Count == 1 && m.IsString(0),
                m => m.GetString(0).Length == 0 ? null : m.GetString(0), timeout);
        }

        /// <summary>The preset a channel last got, or null; blocks up to the timeout.</summary>
        public string GetPreset(int channel = 1, TimeSpan? timeout = null) { return Wait(GetPresetAsync(channel, timeout)); }

        /// <summary>
        /// Which layer a channel plays: "knobs" (its own knobs), "sources" (touch sources reach it) or "clip"
        /// (a clip drives it).
        /// </summary>
        public Task<string> GetDriverAsync(int channel = 1, TimeSpan? timeout = null)
        {
            return Get(channel, "driver", m => m.Count == 1 && m.IsString(0), m => m.GetString(0), timeout);
        }

        /// <summary>Which layer a channel plays; blocks up to the timeout.</summary>
        public string GetDriver(int channel = 1, TimeSpan? timeout = null) { return Wait(GetDriverAsync(channel, timeout)); }

        /// <summary>What clip a channel plays, where in it, and how many loops are left.</summary>
        public Task<ClipState> GetClipAsync(int channel = 1, TimeSpan? timeout = null)
        {
            return Get(channel, "clip", m => m.Count == 3 && m.IsString(0) && m.IsNumber(1) && m.TypeTags[2] == 'i',
                m => new ClipState(m.GetString(0), m.GetFloat(1), m.GetInt(2)), timeout);
        }

        /// <summary>What clip a channel plays; blocks up to the timeout.</summary>
        public ClipState GetClip(int channel = 1, TimeSpan? timeout = null) { return Wait(GetClipAsync(channel, timeout)); }

        /// <summary>
        /// Any setting of a channel (<c>/vibsynth/ch/{n}/get s what</c>), e.g. one this client has no typed method
        /// for: the reply message in setter form (<c>/vibsynth/ch/{n}/{what} ...</c>).
        /// </summary>
        public Task<OscMessage> GetAsync(int channel, string what, TimeSpan? timeout = null)
        {
            CheckName("setting", what);
            return Get(channel, what, m => true, m => m, timeout);
        }

        /// <summary>Any setting of a channel; blocks up to the timeout.</summary>
        public OscMessage Get(int channel, string what, TimeSpan? timeout = null) { return Wait(GetAsync(channel, what, timeout)); }

        // -------------------------------------------------------------- source queries
        /// <summary>
        /// Any setting of a spatial source (<c>/vibsynth/source/{k}/get s what</c>: pos, texture, intensity, balance,
        /// preset, radius, rolloff, on, speed): the reply message in setter form (<c>/vibsynth/source/{k}/{what} ...</c>).
        /// </summary>
        public Task<OscMessage> GetSourceAsync(int source, string what, TimeSpan? timeout = null)
        {
            CheckName("setting", what);
            return GetSource(source, what, m => true, m => m, timeout);
        }

        /// <summary>Any setting of a spatial source; blocks up to the timeout.</summary>
        public OscMessage GetSource(int source, string what, TimeSpan? timeout = null) { return Wait(GetSourceAsync(source, what, timeout)); }

        /// <summary>A source's position target (x, y, z) in metres.</summary>
        public Task<float[]> GetSourcePositionAsync(int source, TimeSpan? timeout = null)
        {
            return GetSource(source, "pos", m => (m.Count == 2 || m.Count == 3) && m.IsNumber(0) && m.IsNumber(1) && (m.Count == 2 || m.IsNumber(2)),
                m => new[] { m.GetFloat(0), m.GetFloat(1), m.Count == 3 ? m.GetFloat(2) : 0f }, timeout);
        }

        /// <summary>A source's position target (x, y, z) in metres; blocks up to the timeout.</summary>
        public float[] GetSourcePosition(int source, TimeSpan? timeout = null) { return Wait(GetSourcePositionAsync(source, timeout)); }

        /// <summary>A source's intensity and balance.</summary>
        public Task<Texture> GetSourceTextureAsync(int source, TimeSpan? timeout = null)
        {
            return GetSource(source, "texture", m => m.Count == 2 && m.IsNumber(0) && m.IsNumber(1),
                m => new Texture(m.GetFloat(0), m.GetFloat(1)), timeout);
        }

        /// <summary>A source's intensity and balance; blocks up to the timeout.</summary>
        public Texture GetSourceTexture(int source, TimeSpan? timeout = null) { return Wait(GetSourceTextureAsync(source, timeout)); }

        /// <summary>A source's radius in metres.</summary>
        public Task<float> GetSourceRadiusAsync(int source, TimeSpan? timeout = null)
        {
            return GetSource(source, "radius", IsNumber1, m => m.GetFloat(0), timeout);
        }

        /// <summary>A source's radius in metres; blocks up to the timeout.</summary>
        public float GetSourceRadius(int source, TimeSpan? timeout = null) { return Wait(GetSourceRadiusAsync(source, timeout)); }

        /// <summary>A source's roll-off law.</summary>
        public Task<Rolloff> GetSourceRolloffAsync(int source, TimeSpan? timeout = null)
        {
            return GetSource(source, "rolloff", m => m.Count == 1 && m.IsString(0), m => ParseRolloff(m.GetString(0)), timeout);
        }

        /// <summary>A source's roll-off law; blocks up to the timeout.</summary>
        public Rolloff GetSourceRolloff(int source, TimeSpan? timeout = null) { return Wait(GetSourceRolloffAsync(source, timeout)); }

        /// <summary>Is a source on?</summary>
        public Task<bool> GetSourceOnAsync(int source, TimeSpan? timeout = null)
        {
            return GetSource(source, "on", IsFlag, m => m.GetInt(0) != 0, timeout);
        }

        /// <summary>Is a source on? Blocks up to the timeout.</summary>
        public bool GetSourceOn(int source, TimeSpan? timeout = null) { return Wait(GetSourceOnAsync(source, timeout)); }

        /// <summary>Does a source's intensity follow its speed?</summary>
        public Task<bool> GetSourceSpeedAsync(int source, TimeSpan? timeout = null)
        {
            return GetSource(source, "speed", IsFlag, m => m.GetInt(0) != 0, timeout);
        }

        /// <summary>Does a source's intensity follow its speed? Blocks up to the timeout.</summary>
        public bool GetSourceSpeed(int source, TimeSpan? timeout = null) { return Wait(GetSourceSpeedAsync(source, timeout)); }

        /// <summary>The preset a source last got, or null when none.</summary>
        public Task<string> GetSourcePresetAsync(int source, TimeSpan? timeout = null)
        {
            return GetSource(source, "preset", m => m.Count == 1 && m.IsString(0),
                m => m.GetString(0).Length == 0 ? null : m.GetString(0), timeout);
        }

        /// <summary>The preset a source last got, or null; blocks up to the timeout.</summary>
        public string GetSourcePreset(int source, TimeSpan? timeout = null) { return Wait(GetSourcePresetAsync(source, timeout)); }

        // -------------------------------------------------------------- follow queries
        // `/vibsynth/follow/get s gain|gate|range|focus`, answered in setter form; a server without
        // --follow refuses with "follow is not running ..." (VibsynthServerException).

        /// <summary>Follow's gain in dB, as the server holds it.</summary>
        /// <exception cref="VibsynthServerException">The server refused (e.g. follow is not running).</exception>
        /// <exception cref="VibsynthTimeoutException">No answer within the timeout.</exception>
        public Task<float> GetFollowGainAsync(TimeSpan? timeout = null) { return FollowNumber("gain", timeout); }

        /// <summary>Follow's gain in dB; blocks up to the timeout.</summary>
        public float GetFollowGain(TimeSpan? timeout = null) { return Wait(GetFollowGainAsync(timeout)); }

        /// <summary>Follow's gate in dB (the mode's default while the config leaves it unset).</summary>
        public Task<float> GetFollowGateAsync(TimeSpan? timeout = null) { return FollowNumber("gate", timeout); }

        /// <summary>Follow's gate in dB; blocks up to the timeout.</summary>
        public float GetFollowGate(TimeSpan? timeout = null) { return Wait(GetFollowGateAsync(timeout)); }

        /// <summary>Follow's input range in dB (audio mode: the span spread over the intensity knob).</summary>
        public Task<float> GetFollowRangeAsync(TimeSpan? timeout = null) { return FollowNumber("range", timeout); }

        /// <summary>Follow's input range in dB; blocks up to the timeout.</summary>
        public float GetFollowRange(TimeSpan? timeout = null) { return Wait(GetFollowRangeAsync(timeout)); }

        /// <summary>Follow's focus: <c>all</c>, <c>effects</c>, <c>bass</c> or <c>beat</c>.</summary>
        public Task<string> GetFollowFocusAsync(TimeSpan? timeout = null)
        {
            return Query(Prefix + "/follow/", "focus", m => m.Count == 1 && m.IsString(0), m => m.GetString(0), timeout);
        }

        /// <summary>Follow's focus; blocks up to the timeout.</summary>
        public string GetFollowFocus(TimeSpan? timeout = null) { return Wait(GetFollowFocusAsync(timeout)); }

        /// <summary>Does a channel follow the input (false: its knobs play)?</summary>
        public Task<bool> GetFollowAsync(int channel = 1, TimeSpan? timeout = null)
        {
            return Get(channel, "follow", IsFlag, m => m.GetInt(0) != 0, timeout);
        }

        /// <summary>Does a channel follow the input? Blocks up to the timeout.</summary>
        public bool GetFollow(int channel = 1, TimeSpan? timeout = null) { return Wait(GetFollowAsync(channel, timeout)); }

        Task<float> FollowNumber(string name, TimeSpan? timeout)
        {
            return Query(Prefix + "/follow/", name, IsNumber1, m => m.GetFloat(0), timeout);
        }

        // -------------------------------------------------------------- server queries
        /// <summary>The server's status pairs (<c>/vibsynth/status</c>).</summary>
        public Task<VibsynthStatus> StatusAsync(TimeSpan? timeout = null)
        {
            string address = prefix + "/status";
            string want = prefix + "/status.reply";
            return Request(address, Osc.EncodeMessage(address, "", new object[0]),
                reply => reply.Address == want && Shaped(reply, IsPairs), m => new VibsynthStatus(m), timeout);
        }

        static bool IsPairs(OscMessage m)
        {
            if (m.Count % 2 != 0) return false;
            for (int i = 0; i < m.Count; i += 2)
                if (!m.IsString(i)) return false;
            return true;
        }

        /// <summary>The server's status pairs; blocks up to the timeout.</summary>
        public VibsynthStatus Status(TimeSpan? timeout = null) { return Wait(StatusAsync(timeout)); }

        /// <summary>The round trip to the server (<c>/ping</c> -> <c>/pong</c>).</summary>
        public Task<TimeSpan> PingAsync(TimeSpan? timeout = null)
        {
            int token = Interlocked.Increment(ref nextId) & 0x7FFFFFFF;
            string address = prefix + "/ping";
            string want = prefix + "/pong";
            long started = Stopwatch.GetTimestamp();
            return Request(address, Osc.EncodeMessage(address, "i", new object[] { token }),
                reply => reply.Address == want && reply.TypeTags == "i" && (int)reply.Arguments[0] == token,
                reply => TimeSpan.FromSeconds((Stopwatch.GetTimestamp() - started) / (double)Stopwatch.Frequency), timeout);
        }

        /// <summary>The round trip to the server; blocks up to the timeout.</summary>
        public TimeSpan Ping(TimeSpan? timeout = null) { return Wait(PingAsync(timeout)); }

        /// <summary>
        /// Wait until the engine applied every command sent before; fail with every refusal received since the
        /// last Sync / <see cref="TakeErrors"/> (a <see cref="VibsynthServerException"/> listing them all).
        /// </summary>
        public Task SyncAsync(TimeSpan? timeout = null) { return SyncCore(timeout); }

        Task<bool> SyncCore(TimeSpan? timeout)
        {
            int id = Interlocked.Increment(ref nextId) & 0x7FFFFFFF;
            string address = prefix + "/sync";
            string want = prefix + "/synced";
            // runs on the receive thread, in arrival order: every error about an earlier command is queued by now
            return Request<bool>(address, Osc.EncodeMessage(address, "i", new object[] { id }),
                reply => reply.Address == want && reply.TypeTags == "i" && (int)reply.Arguments[0] == id,
                reply =>
                {
                    List<VibsynthError> refused = DrainErrors();
                    if (refused.Count > 0) throw new VibsynthServerException(refused);
                    return true;
                }, timeout);
        }

        /// <summary>Wait until the engine applied every earlier command; throw the refusals since the last check.</summary>
        public void Sync(TimeSpan? timeout = null) { Wait(SyncCore(timeout)); }

        /// <summary>The refusals received and not yet reported by <see cref="Sync"/> or here; clears them.</summary>
        public IList<VibsynthError> TakeErrors() { return DrainErrors(); }

        List<VibsynthError> DrainErrors()
        {
            lock (pendingGate)
            {
                var list = new List<VibsynthError>(errors);
                errors.Clear();
                return list;
            }
        }

        // -------------------------------------------------------------- receiving
        void ReceiveLoop()
        {
            var buffer = new byte[65536];
            EndPoint from = new IPEndPoint(server.AddressFamily == AddressFamily.InterNetworkV6 ? IPAddress.IPv6Any : IPAddress.Any, 0);
            while (!disposed)
            {
                int count;
                try
                {
                    // Poll with a timeout so Dispose ends the thread on every runtime (closing a socket does
                    // not interrupt a blocking receive everywhere)
                    if (!socket.Poll(100000, SelectMode.SelectRead)) continue;
                    count = socket.ReceiveFrom(buffer, ref from);
                }
                catch (ObjectDisposedException)
                {
                    break;
                }
                catch (SocketException)
                {
                    if (disposed) break;
                    continue; // e.g. an ICMP error of an earlier send: not a reply
                }
                if (!FromServer((IPEndPoint)from))
                {
                    Interlocked.Increment(ref foreignCount);
                    continue;
                }
                Interlocked.Increment(ref receivedCount);
                List<OscReceived> messages = Osc.Decode(buffer, 0, count);
                if (messages == null)
                {
                    Interlocked.Increment(ref malformedCount);
                    continue;
                }
                foreach (OscReceived received in messages) Dispatch(received);
            }
        }

        bool FromServer(IPEndPoint from)
        {
            if (from.Port != server.Port) return false;
            IPAddress a = from.Address, b = server.Address;
            if (a.IsIPv4MappedToIPv6) a = a.MapToIPv4();
            if (b.IsIPv4MappedToIPv6) b = b.MapToIPv4();
            return a.Equals(b);
        }

        void Dispatch(OscReceived received)
        {
            OscMessage message = received.Message;
            PendingRequest taken = null;
            VibsynthError error = null;
            if (message.Address == prefix + "/error")
            {
                Interlocked.Increment(ref errorCount);
                if (message.Count < 2 || !message.IsString(0) || !message.IsString(1))
                {
                    Interlocked.Increment(ref malformedCount);
                    return;
                }
                error = new VibsynthError(message.GetString(0), message.GetString(1));
                lock (pendingGate)
                {
                    for (LinkedListNode<PendingRequest> node = pending.First; node != null; node = node.Next)
                    {
                        if (node.Value.RequestAddress == error.Address)
                        {
                            taken = node.Value;
                            pending.Remove(node);
                            break;
                        }
                    }
                    if (taken == null)
                    {
                        if (errors.Count == MaxPendingErrors) errors.Dequeue();
                        errors.Enqueue(error);
                    }
                }
                if (taken != null)
                    taken.Fail(new VibsynthServerException(new[] { error }));
                else
                    Raise(ErrorReceived, new VibsynthErrorEventArgs(error));
                return;
            }
            lock (pendingGate)
            {
                for (LinkedListNode<PendingRequest> node = pending.First; node != null; node = node.Next)
                {
                    bool matches;
                    try
                    {
                        matches = node.Value.Matches(message);
                    }
                    catch (Exception)
                    {
                        matches = false; // a user predicate (RequestAsync) that failed: not its reply
                    }
                    if (matches)
                    {
                        taken = node.Value;
                        pending.Remove(node);
                        break;
                    }
                }
            }
            if (taken != null)
            {
                taken.Complete(message);
                return;
            }
            Interlocked.Increment(ref ignoredCount);
            Raise(MessageReceived, new OscMessageEventArgs(received));
        }

        void Raise<TArgs>(EventHandler<TArgs> handler, TArgs args) where TArgs : EventArgs
        {
            if (handler == null) return;
            try
            {
                handler(this, args);
            }
            catch (Exception)
            {
                Interlocked.Increment(ref handlerFailureCount); // a handler's bug must not stop the replies
            }
        }

        // -------------------------------------------------------------- lifetime
        /// <summary>Close the socket and stop the receive thread; waiting queries fail with ObjectDisposedException. Idempotent.</summary>
        public void Dispose()
        {
            List<PendingRequest> waiting;
            lock (sendGate)
            {
                if (disposed) return;
                disposed = true;
                lock (pendingGate)
                {
                    waiting = new List<PendingRequest>(pending);
                    pending.Clear();
                }
            }
            foreach (PendingRequest request in waiting) request.Fail(new ObjectDisposedException("VibsynthClient", "the client was disposed while waiting for a reply"));
            if (Thread.CurrentThread != receiver) receiver.Join(1000);
            socket.Close();
        }

        public override string ToString()
        {
            return string.Format(CultureInfo.InvariantCulture, "VibsynthClient {0}:{1} prefix=\"{2}\"{3}", host, port, prefix, disposed ? " (disposed)" : "");
        }
    }

    // ================================================================== discovery: mDNS + OSCQuery

    /// <summary>
    /// An OSCQuery service found on the network (a vibsynth server, or any other), resolved to an OSC
    /// endpoint or not.
    /// </summary>
    /// <remarks>
    /// A service is <see cref="Resolved"/> once its mDNS SRV record (the OSCQuery port) and its HOST_INFO's
    /// OSC_PORT both answered within the timeout. An unresolved one has no endpoint: <see cref="OscHost"/>
    /// and <see cref="OscPort"/> throw <see cref="VibsynthException"/> with <see cref="Unresolved"/>'s reason,
    /// so a port that was never received (0) cannot be handed out.
    /// </remarks>
    public sealed class VibsynthService
    {
        string oscHost;
        int oscPort;

        /// <summary>The mDNS instance name (discovery.name of the server, e.g. "vibsynth on studio-pc").</summary>
        public string Name { get; internal set; }
        /// <summary>Its OSCQuery server, e.g. "http://192.168.1.5:9572/" (null: its SRV record never answered).</summary>
        public string OscQueryUrl { get; internal set; }
        /// <summary>Why it has no OSC endpoint (null when <see cref="Resolved"/>), e.g. "no SRV record within 2 s".</summary>
        public string Unresolved { get; internal set; }
        /// <summary>True when <see cref="OscHost"/> and <see cref="OscPort"/> hold an endpoint the service named.</summary>
        public bool Resolved { get { return Unresolved == null; } }

        /// <summary>Where it takes OSC: HOST_INFO's OSC_IP (the service's address when HOST_INFO names none).</summary>
        /// <exception cref="VibsynthException">The service is not <see cref="Resolved"/>.</exception>
        public string OscHost { get { Check(); return oscHost; } internal set { oscHost = value; } }
        /// <summary>HOST_INFO's OSC_PORT (1..65535).</summary>
        /// <exception cref="VibsynthException">The service is not <see cref="Resolved"/>.</exception>
        public int OscPort { get { Check(); return oscPort; } internal set { oscPort = value; } }
        /// <summary>HOST_INFO's OSC_TRANSPORT ("UDP").</summary>
        public string OscTransport { get; internal set; }

        void Check()
        {
            if (Unresolved != null)
                throw new VibsynthException("OSCQuery service '" + Name + "' is unresolved: " + Unresolved);
        }

        public override string ToString()
        {
            if (Unresolved != null)
                return Name + ": unresolved (" + Unresolved + ")";
            return string.Format(CultureInfo.InvariantCulture, "{0}: osc {1}://{2}:{3}, oscquery {4}",
                Name, (OscTransport ?? "UDP").ToLowerInvariant(), oscHost, oscPort, OscQueryUrl);
        }
    }

    /// <summary>
    /// Finds vibsynth servers by mDNS (the _oscjson._tcp services they advertise) and reads each one's
    /// OSCQuery HOST_INFO for its OSC address, so a client needs no hard-coded port.
    /// </summary>
    /// <remarks>
    /// One-shot mDNS queries (RFC 6762 section 5.1: sent from an ephemeral port, answered by unicast),
    /// repeated every 250 ms for the timeout, asking for the SRV record of each service whose PTR came
    /// without one; then HTTP GETs of "?HOST_INFO" per service (retried every 250 ms for up to the
    /// timeout, all services at once). A service whose SRV record or HOST_INFO's OSC_PORT did not answer
    /// in time is listed unresolved, with the reason, never with a port it did not receive.
    /// Blocking: call it from a worker thread (or <see cref="DiscoverAsync"/>), not Unity's main thread.
    /// </remarks>
    public static class VibsynthDiscovery
    {
        /// <summary>The OSCQuery service type (Vidvox's OSCQueryProposal).</summary>
        public const string ServiceType = "_oscjson._tcp.local";
        const int MdnsPort = 5353;
        const int MaxHostInfo = 65536;
        const int RetryMs = 250;
        static readonly IPAddress MdnsGroup = IPAddress.Parse("224.0.0.251");

        /// <summary>
        /// The OSCQuery services that answered within <paramref name="timeout"/>, by name: resolved ones, and
        /// those whose SRV record or HOST_INFO did not answer (<see cref="VibsynthService.Resolved"/> false).
        /// </summary>
        /// <remarks>Takes the timeout for mDNS, then up to the timeout again for HOST_INFO.</remarks>
        public static IList<VibsynthService> Discover(TimeSpan timeout)
        {
            var services = Browse(timeout, null);
            ReadHostInfos(services, timeout);
            services.Sort((a, b) => string.CompareOrdinal(a.Name, b.Name));
            return services;
        }

        /// <summary>HOST_INFO of every service whose SRV record answered, all at once, for up to the timeout.</summary>
        static void ReadHostInfos(List<VibsynthService> services, TimeSpan timeout)
        {
            var deadline = DateTime.UtcNow + timeout;
            var fetches = new List<Task>();
            foreach (var service in services)
            {
                if (service.Resolved)
                {
                    var s = service;
                    fetches.Add(Task.Run(() => ReadHostInfo(s, deadline, timeout)));
                }
            }
            Task.WaitAll(fetches.ToArray());
        }

        /// <summary><see cref="Discover"/> on the thread pool.</summary>
        public static Task<IList<VibsynthService>> DiscoverAsync(TimeSpan timeout)
        {
            return Task.Run(() => Discover(timeout));
        }

        /// <summary>
        /// A client for the first resolved service whose name contains <paramref name="nameContains"/> (null:
        /// any); VibsynthException when none answered, or when those that did are unresolved (with why).
        /// </summary>
        /// <remarks>
        /// Browses until a matching service's SRV record answers (at most the timeout), then reads the
        /// HOST_INFO of the matching services found by then (up to the timeout again).
        /// </remarks>
        public static VibsynthClient Connect(string nameContains = null, TimeSpan? timeout = null)
        {
            var wait = timeout ?? TimeSpan.FromSeconds(2);
            Func<string, bool> matches = name => nameContains == null || name.IndexOf(nameContains, StringComparison.Ordinal) >= 0;
            var services = Browse(wait, matches).FindAll(service => matches(service.Name));
            ReadHostInfos(services, wait);
            services.Sort((a, b) => string.CompareOrdinal(a.Name, b.Name));
            string unresolved = null;
            foreach (var service in services)
            {
                if (service.Resolved)
                    return new VibsynthClient(service.OscHost, service.OscPort);
                if (unresolved == null)
                    unresolved = "OSCQuery service '" + service.Name + "' found over mDNS but unresolved: " + service.Unresolved;
            }
            if (unresolved != null)
                throw new VibsynthException(unresolved);
            throw new VibsynthException(nameContains == null
                ? "no OSCQuery service found over mDNS"
                : "no OSCQuery service named like '" + nameContains + "' found over mDNS");
        }

        /// <summary>
        /// The mDNS query, unicast-response bit set on each question: PTR for the service type, and SRV for
        /// each of <paramref name="srvOf"/> (instances whose PTR came without their SRV record).
        /// </summary>
        internal static byte[] Query(ICollection<string> srvOf = null)
        {
            int count = 1 + (srvOf == null ? 0 : srvOf.Count);
            var bytes = new List<byte> { 0, 0, 0, 0, (byte)(count >> 8), (byte)count, 0, 0, 0, 0, 0, 0 };
            AddQuestion(bytes, ServiceType, 12);
            if (srvOf != null)
                foreach (var instance in srvOf)
                    AddQuestion(bytes, instance, 33);
            return bytes.ToArray();
        }

        static void AddQuestion(List<byte> bytes, string name, int type)
        {
            foreach (var label in SplitName(name))
            {
                var raw = Encoding.UTF8.GetBytes(label);
                int length = Math.Min(raw.Length, 63);  // a DNS label's limit (a longer one cannot have been received)
                bytes.Add((byte)length);
                for (int k = 0; k < length; k++)
                    bytes.Add(raw[k]);
            }
            bytes.AddRange(new byte[] { 0, 0, (byte)type, 0x80, 1 });
        }

        /// <summary>An instance name's labels: its first label (the service name) may hold dots.</summary>
        static IEnumerable<string> SplitName(string name)
        {
            string suffix = "." + ServiceType;
            if (name.EndsWith(suffix, StringComparison.OrdinalIgnoreCase) && name.Length > suffix.Length)
            {
                yield return name.Substring(0, name.Length - suffix.Length);
                name = ServiceType;
            }
            foreach (var label in name.Split('.'))
                yield return label;
        }

        /// <summary>
        /// The services whose PTR answered within the timeout (or until the SRV record of one whose name
        /// <paramref name="enough"/> accepts answered): with their OSCQuery URL when their SRV record
        /// answered too, else unresolved.
        /// </summary>
        static List<VibsynthService> Browse(TimeSpan timeout, Func<string, bool> enough)
        {
            string suffix = "." + ServiceType;
            var instances = new HashSet<string>();
            var srv = new Dictionary<string, KeyValuePair<string, int>>();
            var hosts = new Dictionary<string, string>();
            var senders = new Dictionary<string, string>();
            using (var socket = new UdpClient(new IPEndPoint(IPAddress.Any, 0)))
            {
                var deadline = DateTime.UtcNow + timeout;
                var nextQuery = DateTime.UtcNow;
                while (DateTime.UtcNow < deadline)
                {
                    if (DateTime.UtcNow >= nextQuery)
                    {
                        var pending = new List<string>();
                        foreach (var instance in instances)
                            if (!srv.ContainsKey(instance))
                                pending.Add(instance);
                        var query = Query(pending);
                        try { socket.Send(query, query.Length, new IPEndPoint(MdnsGroup, MdnsPort)); }
                        catch (SocketException) { }
                        nextQuery = DateTime.UtcNow + TimeSpan.FromMilliseconds(RetryMs);
                    }
                    var wait = Math.Min((deadline - DateTime.UtcNow).TotalMilliseconds, (nextQuery - DateTime.UtcNow).TotalMilliseconds);
                    if (wait <= 0 || !socket.Client.Poll((int)(wait * 1000), SelectMode.SelectRead))
                        continue;
                    var from = new IPEndPoint(IPAddress.Any, 0);
                    byte[] packet;
                    try { packet = socket.Receive(ref from); }
                    catch (SocketException) { continue; }
                    try { Parse(packet, from.Address.ToString(), instances, srv, hosts, senders); }
                    catch (IndexOutOfRangeException) { }  // a truncated answer: skip it
                    catch (FormatException) { }
                    if (enough != null && Found(instances, srv, enough, suffix))
                        break;
                }
            }
            var found = new Dictionary<string, VibsynthService>();
            foreach (var instance in instances)
            {
                string name = InstanceName(instance, suffix);
                var service = new VibsynthService { Name = name, OscTransport = "UDP" };
                found[name] = service;
                KeyValuePair<string, int> target;
                if (!srv.TryGetValue(instance, out target))
                {
                    service.Unresolved = string.Format(CultureInfo.InvariantCulture,
                        "no SRV record (its OSCQuery port) answered within {0:0.###} s", timeout.TotalSeconds);
                    continue;
                }
                if (target.Value == 0)
                {
                    service.Unresolved = "its SRV record names port 0";
                    continue;
                }
                string address;
                if (!hosts.TryGetValue(target.Key, out address))
                    address = senders[instance];
                service.OscQueryUrl = string.Format(CultureInfo.InvariantCulture, "http://{0}:{1}/", address, target.Value);
                service.OscHost = address;
            }
            return new List<VibsynthService>(found.Values);
        }

        /// <summary>True when an instance <paramref name="enough"/> accepts has its SRV record.</summary>
        static bool Found(HashSet<string> instances, Dictionary<string, KeyValuePair<string, int>> srv, Func<string, bool> enough, string suffix)
        {
            foreach (var instance in instances)
                if (srv.ContainsKey(instance) && enough(InstanceName(instance, suffix)))
                    return true;
            return false;
        }

        static string InstanceName(string instance, string suffix)
        {
            return instance.EndsWith(suffix, StringComparison.OrdinalIgnoreCase) ? instance.Substring(0, instance.Length - suffix.Length) : instance;
        }

        /// <summary>Reads PTR, SRV and A records of one mDNS message (answers and additional records).</summary>
        internal static void Parse(byte[] p, string sender, HashSet<string> instances,
            Dictionary<string, KeyValuePair<string, int>> srv, Dictionary<string, string> hosts, Dictionary<string, string> senders)
        {
            if (p.Length < 12 || (p[2] & 0x80) == 0)
                return;  // not a response
            int questions = (p[4] << 8) | p[5];
            int records = ((p[6] << 8) | p[7]) + ((p[8] << 8) | p[9]) + ((p[10] << 8) | p[11]);
            int i = 12;
            for (int q = 0; q < questions; q++)
            {
                ReadName(p, ref i);
                i += 4;
            }
            for (int r = 0; r < records && i < p.Length; r++)
            {
                string name = ReadName(p, ref i);
                int type = (p[i] << 8) | p[i + 1];
                int length = (p[i + 8] << 8) | p[i + 9];
                int data = i + 10;
                if (data + length > p.Length)
                    throw new IndexOutOfRangeException();
                if (type == 12 && string.Equals(name, ServiceType, StringComparison.OrdinalIgnoreCase))
                {
                    int at = data;
                    string instance = ReadName(p, ref at);
                    instances.Add(instance);
                    senders[instance] = sender;
                }
                else if (type == 33 && length >= 7)
                {
                    int port = (p[data + 4] << 8) | p[data + 5];
                    int at = data + 6;
                    srv[name] = new KeyValuePair<string, int>(ReadName(p, ref at), port);
                    if (!senders.ContainsKey(name))
                        senders[name] = sender;
                }
                else if (type == 1 && length == 4)
                {
                    hosts[name] = string.Format(CultureInfo.InvariantCulture, "{0}.{1}.{2}.{3}", p[data], p[data + 1], p[data + 2], p[data + 3]);
                }
                i = data + length;
            }
        }

        /// <summary>A (possibly compressed) DNS name at <paramref name="i"/>, dotted, without the root's dot.</summary>
        static string ReadName(byte[] p, ref int i)
        {
            var labels = new List<string>();
            int at = i, jumps = 0;
            bool jumped = false;
            while (true)
            {
                int length = p[at];
                if ((length & 0xC0) == 0xC0)
                {
                    if (++jumps > 16)
                        throw new FormatException("DNS name pointers loop");
                    int target = ((length & 0x3F) << 8) | p[at + 1];
                    if (!jumped)
                        i = at + 2;
                    jumped = true;
                    at = target;
                    continue;
                }
                if (length == 0)
                {
                    if (!jumped)
                        i = at + 1;
                    break;
                }
                if (at + 1 + length > p.Length)
                    throw new IndexOutOfRangeException();
                labels.Add(Encoding.UTF8.GetString(p, at + 1, length));
                at += 1 + length;
            }
            return string.Join(".", labels);
        }

        /// <summary>
        /// GET url?HOST_INFO until it answers or <paramref name="deadline"/> (every 250 ms): fills the OSC
        /// address from it, or says why the service is unresolved.
        /// </summary>
        static void ReadHostInfo(VibsynthService service, DateTime deadline, TimeSpan timeout)
        {
            string text = null, failure = "no answer";
            while (true)
            {
                var left = deadline - DateTime.UtcNow;
                if (left <= TimeSpan.Zero)
                    break;
                var attempt = DateTime.UtcNow;
                try
                {
                    text = Get(service.OscQueryUrl + "?HOST_INFO", left);
                    break;
                }
                catch (WebException exc)
                {
                    failure = exc.Message;
                }
                catch (System.IO.IOException exc)
                {
                    failure = exc.Message;
                }
                var pause = attempt + TimeSpan.FromMilliseconds(RetryMs) - DateTime.UtcNow;
                if (pause > TimeSpan.Zero && DateTime.UtcNow + pause < deadline)
                    Thread.Sleep(pause);
            }
            if (text == null)
            {
                service.Unresolved = string.Format(CultureInfo.InvariantCulture,
                    "its HOST_INFO ({0}?HOST_INFO) did not answer within {1:0.###} s ({2})",
                    service.OscQueryUrl, timeout.TotalSeconds, failure);
                return;
            }
            var ip = System.Text.RegularExpressions.Regex.Match(text, "\"OSC_IP\"\\s*:\\s*\"([^\"\\\\]*)\"");
            var port = System.Text.RegularExpressions.Regex.Match(text, "\"OSC_PORT\"\\s*:\\s*(\\d{1,5})(?![\\d.])");
            var transport = System.Text.RegularExpressions.Regex.Match(text, "\"OSC_TRANSPORT\"\\s*:\\s*\"([A-Za-z]+)\"");
            int number = port.Success ? int.Parse(port.Groups[1].Value, CultureInfo.InvariantCulture) : 0;
            if (number < 1 || number > 65535)
            {
                service.Unresolved = "its HOST_INFO (" + service.OscQueryUrl + "?HOST_INFO) names no OSC_PORT in 1..65535";
                return;
            }
            if (ip.Success && ip.Groups[1].Value.Length > 0 && ip.Groups[1].Value != "0.0.0.0")
                service.OscHost = ip.Groups[1].Value;
            service.OscPort = number;
            if (transport.Success)
                service.OscTransport = transport.Groups[1].Value;
        }

        /// <summary>One bounded HTTP GET (up to 64 KiB of the body, as UTF-8).</summary>
        static string Get(string url, TimeSpan timeout)
        {
            var request = (HttpWebRequest)WebRequest.Create(url);
            request.Timeout = (int)Math.Max(100, timeout.TotalMilliseconds);
            request.ReadWriteTimeout = request.Timeout;
            request.Proxy = null;
            using (var response = request.GetResponse())
            using (var stream = response.GetResponseStream())
            {
                var buffer = new byte[MaxHostInfo];
                int total = 0, n;
                while (total < buffer.Length && (n = stream.Read(buffer, total, buffer.Length - total)) > 0)
                    total += n;
                return Encoding.UTF8.GetString(buffer, 0, total);
            }
        }
    }
}
