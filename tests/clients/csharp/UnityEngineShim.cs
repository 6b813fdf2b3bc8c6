// UnityEngineShim.cs: the few UnityEngine types clients/csharp/Unity/VibsynthContactSource.cs uses, with
// the same names and signatures, for the tests only. Compiling the example against it catches a typo
// or a misused API; UnityCheck.cs also drives the component through it against a real server.
// Behaviour is the documented one for what the example needs (a Transform with position, rotation
// about y and a uniform scale; contacts given by the test); nothing else of Unity is imitated.
// The partial types are extended by the Unity package's test (tests/clients/test_unity_package.py).

using System;

namespace UnityEngine
{
    public partial struct Vector3
    {
        public float x, y, z;

        public Vector3(float x, float y, float z)
        {
            this.x = x;
            this.y = y;
            this.z = z;
        }

        public static Vector3 zero { get { return new Vector3(0f, 0f, 0f); } }
        public float magnitude { get { return (float)Math.Sqrt(x * x + y * y + z * z); } }

        public static Vector3 operator +(Vector3 a, Vector3 b) { return new Vector3(a.x + b.x, a.y + b.y, a.z + b.z); }
        public static Vector3 operator -(Vector3 a, Vector3 b) { return new Vector3(a.x - b.x, a.y - b.y, a.z - b.z); }
        public static Vector3 operator *(Vector3 a, float d) { return new Vector3(a.x * d, a.y * d, a.z * d); }
        public static Vector3 operator /(Vector3 a, float d) { return new Vector3(a.x / d, a.y / d, a.z / d); }

        public override string ToString() { return "(" + x + ", " + y + ", " + z + ")"; }
    }

    public class Object
    {
    }

    public partial class Component : Object
    {
    }

    public partial class Transform : Component
    {
        public Vector3 position;
        /// <summary>Rotation about the y axis in degrees (the shim's only rotation).</summary>
        public float yawDegrees;
        public float uniformScale = 1f;

        // world -> local: undo the translation, the rotation about y, then the scale (Unity's order, reversed)
        public Vector3 InverseTransformPoint(Vector3 world)
        {
            Vector3 d = world - position;
            double a = -yawDegrees * Math.PI / 180.0;
            float c = (float)Math.Cos(a), s = (float)Math.Sin(a);
            var local = new Vector3(c * d.x + s * d.z, d.y, -s * d.x + c * d.z);
            return local / uniformScale;
        }
    }

    public class Behaviour : Component
    {
        public bool enabled = true;
    }

    public class MonoBehaviour : Behaviour
    {
    }

    public struct ContactPoint
    {
        public Vector3 point { get; internal set; }

        public static ContactPoint At(Vector3 point)
        {
            var contact = new ContactPoint();
            contact.point = point;
            return contact;
        }
    }

    public partial class Collision
    {
        readonly ContactPoint[] contacts;

        public Collision(params Vector3[] points)
        {
            contacts = new ContactPoint[points.Length];
            for (int i = 0; i < points.Length; i++) contacts[i] = ContactPoint.At(points[i]);
        }

        public int contactCount { get { return contacts.Length; } }
        public ContactPoint GetContact(int index) { return contacts[index]; }
    }

    public static class Time
    {
        public static float time { get; set; }
    }

    public static partial class Mathf
    {
        public static float Abs(float f) { return Math.Abs(f); }
        public static int Clamp(int value, int min, int max) { return value < min ? min : value > max ? max : value; }
        public static float Clamp(float value, float min, float max) { return value < min ? min : value > max ? max : value; }
    }

    public static class Debug
    {
        public static int Warnings, Errors;
        public static string LastMessage;

        public static void LogWarning(object message)
        {
            System.Threading.Interlocked.Increment(ref Warnings);
            LastMessage = Convert.ToString(message);
            Console.Error.WriteLine("warning: " + message);
        }

        public static void LogError(object message)
        {
            System.Threading.Interlocked.Increment(ref Errors);
            LastMessage = Convert.ToString(message);
            Console.Error.WriteLine("error: " + message);
        }
    }

    [AttributeUsage(AttributeTargets.Field)]
    public class PropertyAttribute : Attribute
    {
    }

    [AttributeUsage(AttributeTargets.Field)]
    public sealed class HeaderAttribute : PropertyAttribute
    {
        public readonly string header;
        public HeaderAttribute(string header) { this.header = header; }
    }

    [AttributeUsage(AttributeTargets.Field)]
    public sealed class TooltipAttribute : PropertyAttribute
    {
        public readonly string tooltip;
        public TooltipAttribute(string tooltip) { this.tooltip = tooltip; }
    }

    [AttributeUsage(AttributeTargets.Field)]
    public sealed class RangeAttribute : PropertyAttribute
    {
        public readonly float min, max;
        public RangeAttribute(float min, float max) { this.min = min; this.max = max; }
    }

    [AttributeUsage(AttributeTargets.Class)]
    public sealed class AddComponentMenu : Attribute
    {
        public AddComponentMenu(string menuName) { }
    }

    [AttributeUsage(AttributeTargets.Class)]
    public sealed class DisallowMultipleComponent : Attribute
    {
    }
}
