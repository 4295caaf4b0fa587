// A verdant scene folder (out/<scene>/) read for Unity: manifest.json, the placement tables (CSV or
// binary) and what the importer makes of them. Plain C# (System only), so it also compiles and runs
// outside Unity: scripts/check.sh step 5g3 runs it with Mono on every built scene
// (scripts/engines/unity/check/CheckVerdantData.cs).
//
// Coordinates: glTF is right-handed, +Y up; Unity left-handed, +Y up. glTFast (the glTF importer
// Unity ships as com.unity.cloud.gltfast) mirrors X: a point (x, y, z) becomes (-x, y, z), a rotation
// (x, y, z, w) becomes (x, -y, -z, w), a scale stays. An instance's transform M therefore becomes
// F M F with F = diag(-1, 1, 1), which is what ToUnity returns, so every instance lands on the mesh
// glTFast made exactly where scene.glb draws it.
using System;
using System.Collections.Generic;
using System.Globalization;
using System.IO;
using System.Text;

namespace Verdant
{
    /// <summary>One placement table row, in glTF's frame (metres).</summary>
    public struct Row
    {
        public double X, Y, Z;
        public float Qx, Qy, Qz, Qw;
        public float Sx, Sy, Sz;
        public uint Tile, Variant;
    }

    /// <summary>A row's transform in Unity's frame: position, rotation (x, y, z, w), scale.</summary>
    public struct UnityTrs
    {
        public float Px, Py, Pz;
        public float Qx, Qy, Qz, Qw;
        public float Sx, Sy, Sz;
    }

    /// <summary>One level of a chain: its file (scene-relative), mesh name and switch distance.</summary>
    public class Level
    {
        public string File;
        public string Mesh;
        public int Triangles;
        public double SwitchDistanceM;
        public double ScreenSize;
    }

    /// <summary>What the importer makes of one species' built variant: a prefab with a LODGroup and
    /// its instances, grouped by placement tile.</summary>
    public class VariantPlan
    {
        public string Species;
        public int Variant;
        public List<Level> Levels = new List<Level>();
        /// <summary>LODGroup.size: the bounding sphere's diameter (m) at instance scale 1.</summary>
        public double SizeM;
        /// <summary>LODGroup.localReferencePoint's height (m).</summary>
        public double CentreYM;
        /// <summary>The levels the LODGroup shows (indices into Levels): a level whose range of
        /// screen sizes is empty (LoD0 when LoD1 already meets the budget at distance 0, a level
        /// whose switch equals the next one's, levels beyond the cull distance) is left out.</summary>
        public List<int> Shown = new List<int>();
        /// <summary>Per shown level, LOD[k].screenRelativeTransitionHeight: where the next shown
        /// level takes over (its screen size), for the last the size at the cull distance (0: never
        /// culled). Strictly decreasing, as Unity requires.</summary>
        public List<double> Transitions = new List<double>();
        public double CullDistanceM;
        public SortedDictionary<uint, List<Row>> Tiles = new SortedDictionary<uint, List<Row>>();

        public int Count
        {
            get
            {
                int n = 0;
                foreach (var t in Tiles.Values) n += t.Count;
                return n;
            }
        }
    }

    public static class SceneData
    {
        public static UnityTrs ToUnity(Row r)
        {
            return new UnityTrs
            {
                Px = (float)-r.X, Py = (float)r.Y, Pz = (float)r.Z,
                Qx = r.Qx, Qy = -r.Qy, Qz = -r.Qz, Qw = r.Qw,
                Sx = r.Sx, Sy = r.Sy, Sz = r.Sz,
            };
        }

        public static Dictionary<string, object> ReadManifest(string sceneDir)
        {
            var text = File.ReadAllText(Path.Combine(sceneDir, "manifest.json"), Encoding.UTF8);
            return (Dictionary<string, object>)MiniJson.Parse(text);
        }

        /// <summary>The rows of placements/&lt;species&gt;.csv (x,y,z,qx,qy,qz,qw,sx,sy,sz,yaw_deg,tile,variant)
        /// or .bin (VPLT, version 1, u64 rows, then column arrays; src/export/table_bin.rs).</summary>
        public static List<Row> ReadTable(string path)
        {
            return path.EndsWith(".bin", StringComparison.Ordinal) ? ReadBinary(path) : ReadCsv(path);
        }

        static List<Row> ReadCsv(string path)
        {
            var rows = new List<Row>();
            var ci = CultureInfo.InvariantCulture;
            bool header = true;
            foreach (var line in File.ReadLines(path))
            {
                if (header) { header = false; continue; }
                var c = line.Split(',');
                if (c.Length < 13) continue;
                rows.Add(new Row
                {
                    X = double.Parse(c[0], ci), Y = double.Parse(c[1], ci), Z = double.Parse(c[2], ci),
                    Qx = float.Parse(c[3], ci), Qy = float.Parse(c[4], ci), Qz = float.Parse(c[5], ci), Qw = float.Parse(c[6], ci),
                    Sx = float.Parse(c[7], ci), Sy = float.Parse(c[8], ci), Sz = float.Parse(c[9], ci),
                    Tile = uint.Parse(c[11], ci), Variant = uint.Parse(c[12], ci),
                });
            }
            return rows;
        }

        static List<Row> ReadBinary(string path)
        {
            using (var r = new BinaryReader(File.OpenRead(path)))
            {
                if (Encoding.ASCII.GetString(r.ReadBytes(4)) != "VPLT" || r.ReadUInt32() != 1)
                    throw new InvalidDataException(path + " is not a version 1 binary placement table");
                ulong n64 = r.ReadUInt64();
                if (n64 > int.MaxValue) throw new InvalidDataException(path + ": too many rows");
                int n = (int)n64;
                var rows = new Row[n];
                for (int i = 0; i < n; i++) { rows[i].X = r.ReadDouble(); rows[i].Y = r.ReadDouble(); rows[i].Z = r.ReadDouble(); }
                for (int i = 0; i < n; i++) { rows[i].Qx = r.ReadSingle(); rows[i].Qy = r.ReadSingle(); rows[i].Qz = r.ReadSingle(); rows[i].Qw = r.ReadSingle(); }
                for (int i = 0; i < n; i++) { rows[i].Sx = r.ReadSingle(); rows[i].Sy = r.ReadSingle(); rows[i].Sz = r.ReadSingle(); }
                for (int i = 0; i < n; i++) r.ReadSingle(); // yaw_deg: inside the rotation already
                for (int i = 0; i < n; i++) rows[i].Tile = r.ReadUInt32();
                for (int i = 0; i < n; i++) rows[i].Variant = r.ReadUInt32();
                return new List<Row>(rows);
            }
        }

        static double Num(object o) { return Convert.ToDouble(o, CultureInfo.InvariantCulture); }

        static Dictionary<string, object> Obj(Dictionary<string, object> d, string key)
        {
            object o;
            return d != null && d.TryGetValue(key, out o) ? o as Dictionary<string, object> : null;
        }

        static List<object> Arr(Dictionary<string, object> d, string key)
        {
            object o;
            return d != null && d.TryGetValue(key, out o) && o is List<object> ? (List<object>)o : new List<object>();
        }

        /// <summary>Per species and built variant: levels with screen sizes, the LODGroup's size and
        /// transitions, the cull distance, and the rows by tile.</summary>
        public static List<VariantPlan> Plan(string sceneDir)
        {
            var manifest = ReadManifest(sceneDir);
            var view = Obj(manifest, "view");
            var chains = Obj(view, "chains") ?? new Dictionary<string, object>();
            var views = Arr(view, "views");
            var first = views.Count > 0 ? (Dictionary<string, object>)views[0] : null;
            var lod = Obj(Obj(manifest, "settings"), "lod");
            double tanHalf = Math.Tan((lod != null ? Num(lod["fov_y_deg"]) : 60.0) * Math.PI / 360.0);
            var screen = new Dictionary<string, double>();
            foreach (Dictionary<string, object> p in Arr(manifest, "plants"))
                foreach (Dictionary<string, object> l in Arr(p, "lods"))
                    screen[(string)l["file"]] = l.ContainsKey("screen_size") ? Num(l["screen_size"]) : 1.0;
            var plans = new List<VariantPlan>();
            foreach (Dictionary<string, object> entry in Arr(Obj(manifest, "scatter"), "species"))
            {
                var name = (string)entry["name"];
                var chain = Obj(chains, name);
                if (chain == null) continue;
                double cull = 0;
                if (first != null)
                    foreach (Dictionary<string, object> s in Arr(first, "species"))
                    {
                        var c = Obj(s, "cull");
                        if ((string)s["name"] == name && c != null) cull = Num(c["distance_m"]);
                    }
                var variants = Arr(chain, "variants");
                var pick = Arr(chain, "pick");
                double centre = chain.ContainsKey("centre_y_m") ? Num(chain["centre_y_m"]) : 0.0;
                double height = chain.ContainsKey("height_m") ? Num(chain["height_m"]) : 1.0;
                var byVariant = new SortedDictionary<int, VariantPlan>();
                foreach (var row in ReadTable(Path.Combine(sceneDir, (string)entry["table"])))
                {
                    int built = row.Variant < pick.Count ? (int)Num(pick[(int)row.Variant]) : (int)row.Variant;
                    if (built >= variants.Count)
                        throw new InvalidDataException(entry["table"] + ": a row names variant " + row.Variant + " of " + variants.Count);
                    VariantPlan plan;
                    if (!byVariant.TryGetValue(built, out plan))
                    {
                        plan = new VariantPlan { Species = name, Variant = built, CentreYM = centre, CullDistanceM = cull };
                        foreach (Dictionary<string, object> l in (List<object>)variants[built])
                        {
                            var file = (string)l["file"];
                            plan.Levels.Add(new Level
                            {
                                File = file,
                                Mesh = (string)l["mesh"],
                                Triangles = (int)Num(l["triangles"]),
                                SwitchDistanceM = Num(l["switch_distance_m"]),
                                ScreenSize = screen.ContainsKey(file) ? screen[file] : (plan.Levels.Count == 0 ? 1.0 : 0.0),
                            });
                        }
                        // the sphere behind the screen sizes: size = r / (D tan(fov/2)) at each switch
                        double r = height / 2;
                        foreach (var l in plan.Levels)
                            if (l.SwitchDistanceM > 0 && l.ScreenSize > 0) { r = l.ScreenSize * l.SwitchDistanceM * tanHalf; break; }
                        plan.SizeM = 2 * r;
                        // thresholds s_0 = 1 >= s_1 >= ... and the cull's; level k spans (s_k+1, s_k]
                        double cullSize = cull > 0 ? r / (cull * tanHalf) : 0.0;
                        int n = plan.Levels.Count;
                        Func<int, double> upper = k => k == 0 ? 1.0 : (k < n ? Math.Max(plan.Levels[k].ScreenSize, cullSize) : cullSize);
                        for (int k = 0; k < n; k++)
                            if (upper(k + 1) < upper(k)) { plan.Shown.Add(k); plan.Transitions.Add(upper(k + 1)); }
                        byVariant[built] = plan;
                    }
                    List<Row> tile;
                    if (!plan.Tiles.TryGetValue(row.Tile, out tile)) plan.Tiles[row.Tile] = tile = new List<Row>();
                    tile.Add(row);
                }
                plans.AddRange(byVariant.Values);
            }
            return plans;
        }
    }

    /// <summary>A small JSON reader: objects as Dictionary&lt;string, object&gt;, arrays as
    /// List&lt;object&gt;, numbers as double, strings, booleans and null.</summary>
    public static class MiniJson
    {
        public static object Parse(string s)
        {
            int i = 0;
            var v = Value(s, ref i);
            Ws(s, ref i);
            if (i != s.Length) throw new FormatException("JSON: text after the value at " + i);
            return v;
        }

        static void Ws(string s, ref int i) { while (i < s.Length && char.IsWhiteSpace(s[i])) i++; }

        static object Value(string s, ref int i)
        {
            Ws(s, ref i);
            if (i >= s.Length) throw new FormatException("JSON: unexpected end");
            char c = s[i];
            if (c == '{')
            {
                var d = new Dictionary<string, object>();
                i++;
                Ws(s, ref i);
                if (s[i] == '}') { i++; return d; }
                while (true)
                {
                    Ws(s, ref i);
                    var k = Str(s, ref i);
                    Ws(s, ref i);
                    if (s[i++] != ':') throw new FormatException("JSON: ':' expected at " + (i - 1));
                    d[k] = Value(s, ref i);
                    Ws(s, ref i);
                    if (s[i] == ',') { i++; continue; }
                    if (s[i++] == '}') return d;
                    throw new FormatException("JSON: ',' or '}' expected at " + (i - 1));
                }
            }
            if (c == '[')
            {
                var a = new List<object>();
                i++;
                Ws(s, ref i);
                if (s[i] == ']') { i++; return a; }
                while (true)
                {
                    a.Add(Value(s, ref i));
                    Ws(s, ref i);
                    if (s[i] == ',') { i++; continue; }
                    if (s[i++] == ']') return a;
                    throw new FormatException("JSON: ',' or ']' expected at " + (i - 1));
                }
            }
            if (c == '"') return Str(s, ref i);
            if (s.Length - i >= 4 && string.CompareOrdinal(s, i, "true", 0, 4) == 0) { i += 4; return true; }
            if (s.Length - i >= 5 && string.CompareOrdinal(s, i, "false", 0, 5) == 0) { i += 5; return false; }
            if (s.Length - i >= 4 && string.CompareOrdinal(s, i, "null", 0, 4) == 0) { i += 4; return null; }
            int start = i;
            while (i < s.Length && "+-0123456789.eE".IndexOf(s[i]) >= 0) i++;
            if (i == start) throw new FormatException("JSON: unexpected '" + c + "' at " + i);
            return double.Parse(s.Substring(start, i - start), NumberStyles.Float, CultureInfo.InvariantCulture);
        }

        static string Str(string s, ref int i)
        {
            if (s[i] != '"') throw new FormatException("JSON: string expected at " + i);
            var b = new StringBuilder();
            for (i++; i < s.Length; i++)
            {
                char c = s[i];
                if (c == '"') { i++; return b.ToString(); }
                if (c != '\\') { b.Append(c); continue; }
                char e = s[++i];
                switch (e)
                {
                    case 'n': b.Append('\n'); break;
                    case 't': b.Append('\t'); break;
                    case 'r': b.Append('\r'); break;
                    case 'b': b.Append('\b'); break;
                    case 'f': b.Append('\f'); break;
                    case 'u': b.Append((char)Convert.ToInt32(s.Substring(i + 1, 4), 16)); i += 4; break;
                    default: b.Append(e); break;
                }
            }
            throw new FormatException("JSON: unterminated string");
        }
    }
}
