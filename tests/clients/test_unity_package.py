"""The Unity package (clients/unity/, UPM ``com.vibsynth.client``): one source, valid, compiling.

* the copies of clients/csharp/ in the package are what ``scripts/sync_unity.py`` makes of the
  current sources (edit there; the script writes them);
* ``package.json`` is a valid UPM manifest whose version is vibsynth's;
* every file and folder Unity imports has a ``.meta`` file with a guid unique in the package and
  stable (the MD5 of its path): a package installed from Git is read-only, Unity cannot make them;
* every C# file of the package (the client, the components, the sample) compiles with mcs,
  warnings as errors, against the UnityEngine shim of tests/clients/csharp/UnityEngineShim.cs
  extended here with the few more types the components use (Unity's names and signatures),
  and the clip trigger's gain follows the impact's speed as documented.
"""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import pytest

from tests.clients.mono import UNITY_SHIM, compile_cs, require_mono, run_mono
from vibsynth._version import __version__

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "clients" / "unity"

_spec = importlib.util.spec_from_file_location("sync_unity", ROOT / "scripts" / "sync_unity.py")
assert _spec is not None and _spec.loader is not None
sync_unity = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(sync_unity)

# What the package's components use beyond the contact example's shim (UnityEngineShim.cs).
PACKAGE_SHIM = """
using System;
using System.Collections.Generic;

namespace UnityEngine
{
    public partial struct Vector3
    {
        public static Vector3 one { get { return new Vector3(1f, 1f, 1f); } }
    }

    public partial class Component
    {
        internal GameObject owner;
        public GameObject gameObject { get { return owner; } }
        public Transform transform { get { return owner.transform; } }
    }

    public partial class Transform
    {
        public Vector3 localScale = Vector3.one;
    }

    public partial class Collision
    {
        public Vector3 relativeVelocity { get; set; }
    }

    public static partial class Mathf
    {
        public static float Max(float a, float b) { return Math.Max(a, b); }
        public static float Clamp01(float value) { return Clamp(value, 0f, 1f); }
        public static float Cos(float f) { return (float)Math.Cos(f); }
        public static float Sin(float f) { return (float)Math.Sin(f); }
    }

    public static class Random
    {
        public static float Range(float min, float max) { return min; }
    }

    public enum PrimitiveType { Sphere, Capsule, Cylinder, Cube, Plane, Quad }

    public sealed class GameObject : Object
    {
        readonly List<Component> components = new List<Component>();
        public Transform transform { get; private set; }

        public GameObject() { transform = AddComponent<Transform>(); }

        public static GameObject CreatePrimitive(PrimitiveType type) { return new GameObject(); }

        public T AddComponent<T>() where T : Component, new()
        {
            var component = new T();
            component.owner = this;
            components.Add(component);
            return component;
        }
    }

    public class Collider : Component
    {
        public Rigidbody attachedRigidbody { get; set; }
    }

    public class Rigidbody : Component
    {
        public Vector3 velocity { get; set; }
    }
}
"""

# Drives the clip trigger and the touch source as Unity would, printing key=value lines.
PACKAGE_CHECK = """
using System;
using System.Net;
using System.Net.Sockets;
using System.Reflection;
using UnityEngine;
using Vibsynth;
using Vibsynth.Unity;

public static class PackageCheck
{
    static void Call(object component, string message, params object[] args)
    {
        BindingFlags any = BindingFlags.Instance | BindingFlags.NonPublic | BindingFlags.Public;
        MethodInfo method = component.GetType().GetMethod(message, any);
        method.Invoke(component, args);
    }

    static string Next(UdpClient socket)
    {
        IPEndPoint from = null;
        socket.Client.ReceiveTimeout = 2000;
        try
        {
            var parts = new System.Collections.Generic.List<string>();
            foreach (OscReceived got in Osc.Decode(socket.Receive(ref from))) parts.Add(got.Message.ToString());
            return string.Join(" | ", parts.ToArray());
        }
        catch (SocketException)
        {
            return "none";
        }
    }

    public static int Main()
    {
        var socket = new UdpClient(new IPEndPoint(IPAddress.Loopback, 0));
        int port = ((IPEndPoint)socket.Client.LocalEndPoint).Port;
        var scene = new GameObject();
        VibsynthConnection connection = scene.AddComponent<VibsynthConnection>();
        connection.port = port;
        bool connected = false;
        connection.Connected += c => connected = true;
        Call(connection, "OnEnable");
        Console.WriteLine("connected=" + connected);

        VibsynthClipTrigger trigger = new GameObject().AddComponent<VibsynthClipTrigger>();
        trigger.connection = connection;
        trigger.channel = 2;
        Console.WriteLine("gain.slow=" + trigger.GainFor(0.01f));
        Console.WriteLine("gain.mid=" + trigger.GainFor(1.525f).ToString("R"));
        Console.WriteLine("gain.fast=" + trigger.GainFor(30f));
        Call(trigger, "OnCollisionEnter", new Collision { relativeVelocity = new Vector3(0f, -1.525f, 0f) });
        Console.WriteLine("hit=" + Next(socket));
        var other = new GameObject().AddComponent<Collider>();
        other.attachedRigidbody = new GameObject().AddComponent<Rigidbody>();
        other.attachedRigidbody.velocity = new Vector3(0.01f, 0f, 0f);
        Call(trigger, "OnTriggerEnter", other); // too slow: nothing sent

        var finger = new GameObject();
        finger.transform.position = new Vector3(0.02f, 0f, 0.01f);
        VibsynthTouchSource touch = new GameObject().AddComponent<VibsynthTouchSource>();
        touch.connection = connection;
        touch.target = finger.transform;
        touch.source = 2;
        touch.intensityFromSpeed = false;
        Time.time = 1f;
        Call(touch, "Update");
        Console.WriteLine("start=" + Next(socket));
        Time.time = 1.02f;
        finger.transform.position = new Vector3(0.03f, 0f, 0.01f);
        Call(touch, "Update");
        Console.WriteLine("move=" + Next(socket));
        Time.time = 1.04f;
        Call(touch, "Update"); // not moved: nothing sent
        Call(touch, "OnDisable");
        Console.WriteLine("off=" + Next(socket));
        Call(connection, "OnDisable");
        Console.WriteLine("client_after_disable=" + (connection.Client == null ? "null" : "set"));
        Console.WriteLine("warnings=" + UnityEngine.Debug.Warnings + "," + UnityEngine.Debug.Errors);
        return 0;
    }
}
"""


def _package_sources() -> list[Path]:
    return sorted(PACKAGE.rglob("*.cs"))


def test_the_package_copies_and_meta_files_are_in_step_with_their_sources():
    """Fails when clients/csharp/ changed and scripts/sync_unity.py was not run (or a copy was edited)."""
    expected = sync_unity.expected()
    assert PACKAGE / "Runtime" / "Client" / "VibsynthClient.cs" in expected
    differ = [
        p.relative_to(ROOT).as_posix() for p, text in expected.items() if not p.is_file() or p.read_text() != text
    ]
    assert not differ, f"run python scripts/sync_unity.py: {differ}"
    assert not sync_unity.stale_metas(), "a .meta file without its asset"
    copy = (PACKAGE / "Runtime" / "Client" / "VibsynthClient.cs").read_text()
    assert copy.startswith("// Generated from clients/csharp/VibsynthClient.cs by scripts/sync_unity.py: edit there")
    assert copy.endswith((ROOT / "clients" / "csharp" / "VibsynthClient.cs").read_text())


def test_the_sync_check_fails_on_a_drifted_copy(tmp_path, monkeypatch):
    fake = tmp_path / "unity"
    (fake / "Runtime" / "Client").mkdir(parents=True)
    (fake / "package.json").write_text("{}")
    monkeypatch.setattr(sync_unity, "PACKAGE", fake)
    assert sync_unity.main(["--check"]) == 1  # nothing generated yet
    for path, text in sync_unity.expected(fake).items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    assert sync_unity.main(["--check"]) == 0
    copy = fake / "Runtime" / "Client" / "VibsynthClient.cs"
    copy.write_text(copy.read_text().replace("public sealed class VibsynthClient", "public class VibsynthClient"))
    assert sync_unity.main(["--check"]) == 1
    assert sync_unity.main([]) == 0 and sync_unity.main(["--check"]) == 0  # written again
    (fake / "Runtime" / "Gone.cs.meta").write_text("fileFormatVersion: 2\n")
    assert sync_unity.main(["--check"]) == 1


def test_package_json_is_a_valid_upm_manifest_at_vibsynth_s_version():
    manifest = json.loads((PACKAGE / "package.json").read_text())
    for key in ("name", "version", "unity", "displayName", "description", "author", "license"):
        assert manifest.get(key), key
    name = manifest["name"]
    assert re.fullmatch(r"[a-z0-9._-]+", name) and len(name) <= 214
    assert re.fullmatch(r"[a-z0-9-]+(\.[a-z0-9-]+){2,}", name), "reverse-domain: com.company.package"
    semver = r"(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)(-[0-9A-Za-z.-]+)?(\+[0-9A-Za-z.-]+)?"
    assert re.fullmatch(semver, manifest["version"])
    assert manifest["version"] == __version__, "the package's version is vibsynth's (vibsynth/_version.py)"
    assert re.fullmatch(r"20\d\d\.\d", manifest["unity"])
    assert isinstance(manifest["author"], dict) and manifest["author"]["name"]
    for sample in manifest.get("samples", []):
        assert sample["path"].startswith("Samples~/") and (PACKAGE / sample["path"]).is_dir()
        assert list((PACKAGE / sample["path"]).glob("*.cs"))
    asmdefs = list((PACKAGE / "Runtime").glob("*.asmdef"))
    assert len(asmdefs) == 1
    asmdef = json.loads(asmdefs[0].read_text())
    assert asmdef["name"] == asmdefs[0].stem == "Vibsynth.Runtime" and asmdef["autoReferenced"] is True
    assert (PACKAGE / "README.md").is_file() or (PACKAGE / "Documentation~").is_dir()


def test_every_asset_has_a_meta_file_with_a_unique_stable_guid():
    assets = [p for p in PACKAGE.rglob("*") if p.suffix != ".meta" and "~" not in p.relative_to(PACKAGE).as_posix()]
    assert len(assets) >= 10 and any(p.is_dir() for p in assets)
    guids: dict[str, Path] = {}
    for asset in assets:
        meta = asset.with_name(asset.name + ".meta")
        assert meta.is_file(), f"{asset.relative_to(ROOT)} has no .meta file"
        text = meta.read_text()
        found = re.search(r"^guid: ([0-9a-f]{32})$", text, re.M)
        assert text.startswith("fileFormatVersion: 2\n") and found, meta
        relative = asset.relative_to(PACKAGE).as_posix()
        assert found.group(1) == sync_unity.guid(relative)  # stable: from the path alone
        assert found.group(1) not in guids, (asset, guids.get(found.group(1)))
        guids[found.group(1)] = asset
        assert ("folderAsset: yes" in text) == asset.is_dir()
    # nothing Unity does not import carries one (the ~ folders)
    assert not [p for p in PACKAGE.rglob("*.meta") if "~" in p.relative_to(PACKAGE).as_posix()]


@pytest.fixture(scope="module")
def package_check(tmp_path_factory) -> Path:
    require_mono()
    folder = tmp_path_factory.mktemp("unity-package")
    (folder / "PackageShim.cs").write_text(PACKAGE_SHIM)
    (folder / "PackageCheck.cs").write_text(PACKAGE_CHECK)
    sources = _package_sources()
    assert {p.name for p in sources} >= {
        "VibsynthClient.cs",
        "VibsynthConnection.cs",
        "VibsynthTouchSource.cs",
        "VibsynthClipTrigger.cs",
        "VibsynthContactSource.cs",
        "VibsynthSample.cs",
    }
    return compile_cs(
        folder / "PackageCheck.exe", *sources, UNITY_SHIM, folder / "PackageShim.cs", folder / "PackageCheck.cs"
    )


def test_the_components_compile_and_send_what_the_server_expects(package_check):
    seen = run_mono(package_check)
    assert seen["connected"] == "True"
    # the clip trigger: silent below min speed (0.05), linear up to full speed (3 m/s), capped
    assert float(seen["gain.slow"]) == 0.0
    assert float(seen["gain.mid"]) == pytest.approx(0.5, abs=1e-6)
    assert float(seen["gain.fast"]) == 1.0
    assert seen["hit"].split(" ")[:3] == ["/vibsynth/ch/2/play", "sf", '"impact"']
    assert float(seen["hit"].split(" ")[3]) == pytest.approx(0.5, abs=1e-6)
    # the touch source: one bundle turning it on where the Transform is, then positions as it moves, then off
    start = seen["start"]
    messages = start.split(" | ")  # one datagram: a bundle, applied together
    assert any(m.startswith("/vibsynth/source/2/speed i 0") for m in messages), start
    assert any(m.startswith("/vibsynth/source/2/pos fff 0.02 0 0.01") for m in messages), start
    assert any(m.startswith("/vibsynth/source/2/on i 1") for m in messages), start
    assert seen["move"] == "/vibsynth/source/2/pos fff 0.03 0 0.01"
    assert seen["off"] == "/vibsynth/source/2/on i 0"
    assert seen["client_after_disable"] == "null"
    assert seen["warnings"] == "0,0"
