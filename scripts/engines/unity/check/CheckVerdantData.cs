// Runs the Unity importer's data side (VerdantData.cs) on built scene folders, outside Unity
// (check.sh step 5g3 compiles both with Mono's mcs):
//
//   mcs -out:check.exe scripts/engines/unity/VerdantData.cs scripts/engines/unity/check/CheckVerdantData.cs
//   mono check.exe [--pair CSV_SCENE BINARY_SCENE] out/check/build/demo ...
//
// Per scene: every table row planned once (per species, the manifest's count); each variant's
// levels are the chain's, its LOD transitions 1 > t0 >= t1 >= ... >= 0, and the sphere behind the
// screen sizes is the same at every level's switch (LODGroup.size); every row's Unity transform,
// composed as Unity composes it (T R S), equals F M F of its glTF transform M (F = diag(-1, 1, 1),
// glTFast's mirror) to 1e-5 of its size. --pair: the same scene built with CSV and with binary
// tables reads the same rows from both (to 1e-6). Exits 1 on any failure.
using System;
using System.Collections.Generic;
using Verdant;

static class CheckVerdantData
{
    // rotation matrix of a unit quaternion (x, y, z, w), v' = q v q*
    static double[,] Rot(double x, double y, double z, double w)
    {
        return new double[,]
        {
            { 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w) },
            { 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w) },
            { 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y) },
        };
    }

    static Dictionary<string, string> Tables(string dir)
    {
        var m = SceneData.ReadManifest(dir);
        var t = new Dictionary<string, string>();
        foreach (Dictionary<string, object> e in (List<object>)((Dictionary<string, object>)m["scatter"])["species"])
            t[(string)e["name"]] = System.IO.Path.Combine(dir, (string)e["table"]);
        return t;
    }

    static bool Near(double a, double b) { return Math.Abs(a - b) <= 1e-6 * Math.Max(1.0, Math.Abs(a)); }

    // the same scene built with CSV and with binary tables: every row reads the same from both
    static bool CheckPair(string csvDir, string binDir)
    {
        var problems = new List<string>();
        var a = Tables(csvDir);
        var b = Tables(binDir);
        int rows = 0;
        foreach (var kv in a)
        {
            string other;
            if (!b.TryGetValue(kv.Key, out other) || !other.EndsWith(".bin")) { problems.Add(kv.Key + ": no binary table in " + binDir); continue; }
            var x = SceneData.ReadTable(kv.Value);
            var y = SceneData.ReadTable(other);
            if (x.Count != y.Count) { problems.Add(kv.Key + ": " + x.Count + " CSV rows, " + y.Count + " binary rows"); continue; }
            for (int i = 0; i < x.Count; i++)
            {
                var r = x[i];
                var q = y[i];
                bool same = r.Tile == q.Tile && r.Variant == q.Variant && Near(r.X, q.X) && Near(r.Y, q.Y) && Near(r.Z, q.Z)
                    && Near(r.Qx, q.Qx) && Near(r.Qy, q.Qy) && Near(r.Qz, q.Qz) && Near(r.Qw, q.Qw)
                    && Near(r.Sx, q.Sx) && Near(r.Sy, q.Sy) && Near(r.Sz, q.Sz);
                if (!same) { problems.Add(kv.Key + ": row " + i + " reads differently from the binary table"); break; }
            }
            rows += x.Count;
        }
        Console.WriteLine((problems.Count > 0 ? "FAIL  " : "ok    ") + binDir + ": " + rows + " binary table rows read as their CSV rows"
            + (problems.Count > 0 ? "\n      " + string.Join("\n      ", problems) : ""));
        return problems.Count == 0;
    }

    static int Main(string[] argv)
    {
        int failed = 0;
        var args = new List<string>();
        for (int i = 0; i < argv.Length; i++)
        {
            if (argv[i] == "--pair" && i + 2 < argv.Length)
            {
                if (!CheckPair(argv[i + 1], argv[i + 2])) failed++;
                i += 2;
            }
            else
            {
                args.Add(argv[i]);
            }
        }
        foreach (var dir in args)
        {
            var problems = new List<string>();
            List<VariantPlan> plans;
            Dictionary<string, object> manifest;
            try
            {
                plans = SceneData.Plan(dir);
                manifest = SceneData.ReadManifest(dir);
            }
            catch (Exception e)
            {
                Console.WriteLine("FAIL  " + dir + ": " + e.Message);
                failed++;
                continue;
            }
            var placed = new Dictionary<string, int>();
            double worst = 0;
            int rows = 0;
            foreach (var p in plans)
            {
                int n;
                placed.TryGetValue(p.Species, out n);
                placed[p.Species] = n + p.Count;
                var t = p.Transitions;
                bool ordered = t.Count > 0 && t.Count == p.Shown.Count && t[0] < 1.0 && t[t.Count - 1] >= 0.0;
                for (int k = 1; k < t.Count; k++) ordered &= t[k] < t[k - 1];
                if (!ordered) problems.Add(p.Species + " v" + p.Variant + ": transitions " + string.Join(", ", t) + " are not 1 > t0 > t1 > ... >= 0");
                // a level is left out only when its range is empty: its switch is the next one's
                for (int k = 0; k + 1 < p.Levels.Count; k++)
                    if (!p.Shown.Contains(k) && k > 0 && p.Levels[k].ScreenSize > p.Levels[k + 1].ScreenSize && (p.CullDistanceM == 0 || p.Levels[k].SwitchDistanceM < p.CullDistanceM))
                        problems.Add(p.Levels[k].File + ": left out of the LODGroup though its range is not empty");
                if (!(p.SizeM > 0)) problems.Add(p.Species + " v" + p.Variant + ": LODGroup size " + p.SizeM);
                // the same sphere at every switch: r = size * D * tan(fov/2) (LODGroup.size = 2r)
                var lod = (Dictionary<string, object>)((Dictionary<string, object>)manifest["settings"])["lod"];
                double tanHalf = Math.Tan(Convert.ToDouble(lod["fov_y_deg"]) * Math.PI / 360.0);
                foreach (var l in p.Levels)
                {
                    if (l.SwitchDistanceM <= 0 || l.ScreenSize <= 0) continue;
                    double r = l.ScreenSize * l.SwitchDistanceM * tanHalf;
                    if (Math.Abs(2 * r - p.SizeM) > 1e-6 * p.SizeM) problems.Add(l.File + ": sphere diameter " + 2 * r + " m, the LODGroup's " + p.SizeM);
                }
                foreach (var tile in p.Tiles.Values)
                    foreach (var row in tile)
                    {
                        rows++;
                        var u = SceneData.ToUnity(row);
                        // glTF M = T R S; F M F: linear part F L F, translation F t
                        var lg = Rot(row.Qx, row.Qy, row.Qz, row.Qw);
                        var lu = Rot(u.Qx, u.Qy, u.Qz, u.Qw);
                        double[] sg = { row.Sx, row.Sy, row.Sz }, su = { u.Sx, u.Sy, u.Sz };
                        double[] f = { -1, 1, 1 };
                        double size = Math.Max(Math.Max(Math.Abs(row.Sx), Math.Abs(row.Sy)), Math.Max(Math.Abs(row.Sz), 1e-9));
                        for (int i = 0; i < 3; i++)
                            for (int j = 0; j < 3; j++)
                                worst = Math.Max(worst, Math.Abs(lu[i, j] * su[j] - f[i] * lg[i, j] * sg[j] * f[j]) / size);
                        double[] tg = { row.X, row.Y, row.Z }, tu = { u.Px, u.Py, u.Pz };
                        for (int i = 0; i < 3; i++)
                            worst = Math.Max(worst, Math.Abs(tu[i] - f[i] * tg[i]) / Math.Max(Math.Abs(tg[i]), 1.0) - 1e-7);
                    }
            }
            var chains = (Dictionary<string, object>)((Dictionary<string, object>)manifest["view"])["chains"];
            foreach (Dictionary<string, object> e in (List<object>)((Dictionary<string, object>)manifest["scatter"])["species"])
            {
                var name = (string)e["name"];
                if (!chains.ContainsKey(name)) continue;
                int n;
                placed.TryGetValue(name, out n);
                if (n != (int)Convert.ToDouble(e["count"])) problems.Add(name + ": " + n + " instances planned, the manifest places " + e["count"]);
            }
            if (worst > 1e-5) problems.Add("Unity transforms differ from F M F by up to " + worst.ToString("e2"));
            int total = 0;
            foreach (var n in placed.Values) total += n;
            Console.WriteLine((problems.Count > 0 ? "FAIL  " : "ok    ") + dir + ": " + plans.Count + " LODGroup prefabs, " + total
                + " instances, " + rows + " rows' Unity transforms = F M F (worst " + worst.ToString("e1") + ")"
                + (problems.Count > 0 ? "\n      " + string.Join("\n      ", problems) : ""));
            if (problems.Count > 0) failed++;
        }
        return failed > 0 ? 1 : 0;
    }
}
