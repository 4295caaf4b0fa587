// Imports a verdant scene folder into the open Unity scene (Tools > Verdant > Import Scene Folder).
//
// Needs glTFast (package com.unity.cloud.gltfast), which imports the folder's .glb files as
// assets. Copy (or build) the scene folder inside Assets/, e.g. Assets/Verdant/demo, and put the
// scripts of scripts/engines/unity/ in the project (Editor/ under an Editor folder). It makes:
// - the terrain (terrain/terrain.glb as a prefab instance);
// - per species and built variant, a prefab (Assets/.../<scene>/unity/<species>_v<k>.prefab) with
//   a LODGroup whose levels are the chain's level files, switching at verdant's screen sizes
//   (LOD[k].screenRelativeTransitionHeight = the next level's screen_size, LODGroup.size = the
//   bounding sphere's diameter, so Unity switches where verdant's error budget says; the last
//   level fades out at the species' cull distance of the first view);
// - every placement table row: for a variant with at most MaxGameObjects instances, a prefab
//   instance under a parent per tile; above that (grass), one VerdantInstances component per
//   variant that draws each tile with GPU instancing at the level its distance selects.
// Transforms follow glTFast's mirror of X (see VerdantData.cs), so instances land where scene.glb
// draws them.
using System.Collections.Generic;
using System.IO;
using UnityEditor;
using UnityEngine;

namespace Verdant
{
    public static class VerdantImporter
    {
        /// <summary>Variants with more instances than this are drawn by VerdantInstances.</summary>
        public const int MaxGameObjects = 20000;

        [MenuItem("Tools/Verdant/Import Scene Folder...")]
        static void Menu()
        {
            var dir = EditorUtility.OpenFolderPanel("A verdant scene folder inside Assets/", Application.dataPath, "");
            if (!string.IsNullOrEmpty(dir)) Import(dir);
        }

        /// <summary>The folder as an asset path ("Assets/..."): glTFast imports only what is inside Assets/.</summary>
        static string AssetPath(string dir)
        {
            var full = Path.GetFullPath(dir).Replace('\\', '/');
            var assets = Path.GetFullPath(Application.dataPath).Replace('\\', '/');
            if (!full.StartsWith(assets))
                throw new System.ArgumentException(dir + " is not inside " + assets + ": copy the scene folder into Assets/ first");
            return "Assets" + full.Substring(assets.Length);
        }

        public static GameObject Import(string sceneDir)
        {
            string assetDir = AssetPath(sceneDir);
            AssetDatabase.Refresh();
            var manifest = SceneData.ReadManifest(sceneDir);
            var lod = (Dictionary<string, object>)((Dictionary<string, object>)manifest["settings"])["lod"];
            var root = new GameObject(Path.GetFileName(sceneDir.TrimEnd('/', '\\')));
            Undo.RegisterCreatedObjectUndo(root, "Import verdant scene");

            var terrain = AssetDatabase.LoadAssetAtPath<GameObject>(assetDir + "/terrain/terrain.glb");
            if (terrain != null)
            {
                var t = (GameObject)PrefabUtility.InstantiatePrefab(terrain);
                t.transform.SetParent(root.transform, false);
            }
            else
            {
                Debug.LogWarning("verdant: no terrain/terrain.glb in " + assetDir + " (is glTFast installed?)");
            }

            var plans = SceneData.Plan(sceneDir);
            int objects = 0, drawn = 0;
            try
            {
                for (int i = 0; i < plans.Count; i++)
                {
                    var p = plans[i];
                    EditorUtility.DisplayProgressBar("verdant", p.Species + " v" + p.Variant, (float)i / plans.Count);
                    var prefab = BuildPrefab(p, assetDir);
                    if (prefab == null) continue;
                    var parent = new GameObject(p.Species + "_v" + p.Variant);
                    parent.transform.SetParent(root.transform, false);
                    if (p.Count <= MaxGameObjects)
                        objects += PlaceObjects(p, prefab, parent.transform);
                    else
                        drawn += AddInstancer(p, prefab, parent, lod, assetDir);
                }
            }
            finally
            {
                EditorUtility.ClearProgressBar();
            }
            AssetDatabase.SaveAssets();
            Debug.Log("verdant: " + root.name + ": " + plans.Count + " LODGroup prefabs, " + objects
                + " prefab instances, " + drawn + " instances drawn by VerdantInstances");
            return root;
        }

        /// <summary>The variant's prefab: one child per shown level, a LODGroup over them.</summary>
        static GameObject BuildPrefab(VariantPlan p, string assetDir)
        {
            var go = new GameObject(p.Species + "_v" + p.Variant);
            var lods = new LOD[p.Shown.Count];
            for (int i = 0; i < p.Shown.Count; i++)
            {
                var level = p.Levels[p.Shown[i]];
                var source = AssetDatabase.LoadAssetAtPath<GameObject>(assetDir + "/" + level.File);
                if (source == null)
                {
                    Debug.LogWarning("verdant: cannot load " + assetDir + "/" + level.File);
                    Object.DestroyImmediate(go);
                    return null;
                }
                var child = (GameObject)PrefabUtility.InstantiatePrefab(source);
                child.name = level.Mesh;
                child.transform.SetParent(go.transform, false);
                lods[i] = new LOD((float)p.Transitions[i], child.GetComponentsInChildren<Renderer>());
            }
            var group = go.AddComponent<LODGroup>();
            group.SetLODs(lods);
            group.localReferencePoint = new Vector3(0f, (float)p.CentreYM, 0f);
            group.size = (float)p.SizeM;
            Directory.CreateDirectory(assetDir + "/unity");
            var prefab = PrefabUtility.SaveAsPrefabAsset(go, assetDir + "/unity/" + go.name + ".prefab");
            Object.DestroyImmediate(go);
            return prefab;
        }

        static Matrix4x4 Matrix(Row r)
        {
            var u = SceneData.ToUnity(r);
            return Matrix4x4.TRS(new Vector3(u.Px, u.Py, u.Pz), new Quaternion(u.Qx, u.Qy, u.Qz, u.Qw), new Vector3(u.Sx, u.Sy, u.Sz));
        }

        static int PlaceObjects(VariantPlan p, GameObject prefab, Transform parent)
        {
            int n = 0;
            foreach (var tile in p.Tiles)
            {
                var tileObject = new GameObject("tile" + tile.Key).transform;
                tileObject.SetParent(parent, false);
                foreach (var row in tile.Value)
                {
                    var u = SceneData.ToUnity(row);
                    var o = (GameObject)PrefabUtility.InstantiatePrefab(prefab);
                    o.transform.SetParent(tileObject, false);
                    o.transform.localPosition = new Vector3(u.Px, u.Py, u.Pz);
                    o.transform.localRotation = new Quaternion(u.Qx, u.Qy, u.Qz, u.Qw);
                    o.transform.localScale = new Vector3(u.Sx, u.Sy, u.Sz);
                    n++;
                }
            }
            return n;
        }

        /// <summary>A VerdantInstances over the variant's tiles, its levels' meshes with instanced
        /// copies of their materials (the imported ones are read-only).</summary>
        static int AddInstancer(VariantPlan p, GameObject prefab, GameObject parent, Dictionary<string, object> lod, string assetDir)
        {
            var draw = parent.AddComponent<VerdantInstances>();
            var levels = new List<VerdantInstances.LevelDraw>();
            for (int i = 0; i < p.Shown.Count; i++)
            {
                var level = p.Levels[p.Shown[i]];
                var child = prefab.transform.GetChild(i);
                var filter = child.GetComponentInChildren<MeshFilter>();
                var renderer = child.GetComponentInChildren<MeshRenderer>();
                if (filter == null || renderer == null) continue;
                var materials = new Material[renderer.sharedMaterials.Length];
                for (int m = 0; m < materials.Length; m++)
                {
                    var path = assetDir + "/unity/" + level.Mesh + "_" + m + ".mat";
                    var copy = new Material(renderer.sharedMaterials[m]) { enableInstancing = true };
                    AssetDatabase.CreateAsset(copy, path);
                    materials[m] = copy;
                }
                levels.Add(new VerdantInstances.LevelDraw
                {
                    mesh = filter.sharedMesh,
                    materials = materials,
                    switchDistance = (float)level.SwitchDistanceM,
                });
            }
            draw.levels = levels.ToArray();
            draw.cullDistance = (float)p.CullDistanceM;
            draw.referenceHeightPx = (float)System.Convert.ToDouble(lod["screen_height_px"]);
            draw.referenceFovDeg = (float)System.Convert.ToDouble(lod["fov_y_deg"]);
            var tiles = new List<VerdantInstances.Tile>();
            int n = 0;
            foreach (var tile in p.Tiles)
            {
                var matrices = new Matrix4x4[tile.Value.Count];
                var centre = Vector3.zero;
                float scale = 0f;
                for (int i = 0; i < matrices.Length; i++)
                {
                    matrices[i] = Matrix(tile.Value[i]);
                    centre += (Vector3)matrices[i].GetColumn(3);
                    scale += tile.Value[i].Sy;
                }
                centre /= matrices.Length;
                float radius = 0f;
                foreach (var m in matrices) radius = Mathf.Max(radius, Vector3.Distance(centre, m.GetColumn(3)));
                tiles.Add(new VerdantInstances.Tile { centre = centre, radius = radius, meanScale = scale / matrices.Length, matrices = matrices });
                n += matrices.Length;
            }
            draw.tiles = tiles.ToArray();
            return n;
        }
    }
}
