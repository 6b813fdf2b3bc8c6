// VibsynthSample.cs: the package at work without a scene. Add this script to any GameObject of an
// empty scene and press Play with `vibsynth serve` running on this machine (vibsynth serve --layout
// glove, for a touch source to reach actuators). It builds a connection, a sphere that circles
// 5 cm around the layout's origin as touch source 1, and a floor that plays the "impact" clip, as
// hard as a falling cube hits it, every two seconds.

using UnityEngine;
using Vibsynth.Unity;

public sealed class VibsynthSample : MonoBehaviour
{
    Transform finger;
    Rigidbody cube;
    float nextDrop;

    void Start()
    {
        var connection = gameObject.AddComponent<VibsynthConnection>(); // 127.0.0.1:9570; or useDiscovery = true

        finger = GameObject.CreatePrimitive(PrimitiveType.Sphere).transform;
        finger.localScale = Vector3.one * 0.02f;
        VibsynthTouchSource touch = finger.gameObject.AddComponent<VibsynthTouchSource>();
        touch.connection = connection;
        touch.intensityFromSpeed = true; // felt while it moves

        GameObject floor = GameObject.CreatePrimitive(PrimitiveType.Plane);
        floor.transform.position = new Vector3(0f, -1f, 0f);
        VibsynthClipTrigger trigger = floor.AddComponent<VibsynthClipTrigger>();
        trigger.connection = connection;
        trigger.clip = "impact";

        cube = GameObject.CreatePrimitive(PrimitiveType.Cube).AddComponent<Rigidbody>();
        cube.transform.localScale = Vector3.one * 0.1f;
    }

    void Update()
    {
        float t = Time.time;
        finger.position = new Vector3(0.05f * Mathf.Cos(t), 0f, 0.05f * Mathf.Sin(t));
        if (t < nextDrop) return;
        nextDrop = t + 2f;
        cube.velocity = Vector3.zero;
        cube.transform.position = new Vector3(0f, Random.Range(0f, 1f), 0f); // higher: a harder hit
    }
}
