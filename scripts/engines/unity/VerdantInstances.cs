// Draws one species variant's instances of a verdant scene with GPU instancing, tile by tile: each
// placement tile picks the chain level its distance selects (verdant's switch distances times the
// tile's mean instance scale, scaled to the camera against the preset's [lod] reference screen),
// and tiles beyond the cull distance are not drawn: the selection verdant's view stage makes for
// scene.glb. VerdantImporter uses it for species with more instances than GameObjects should carry
// (grass: 10^5-10^7); smaller species become LODGroup prefab instances instead.
using UnityEngine;

namespace Verdant
{
    public class VerdantInstances : MonoBehaviour
    {
        [System.Serializable]
        public class LevelDraw
        {
            public Mesh mesh;
            /// <summary>One per submesh, with GPU instancing enabled.</summary>
            public Material[] materials;
            /// <summary>Where this level starts (m, at instance scale 1, on the reference screen).</summary>
            public float switchDistance;
        }

        [System.Serializable]
        public class Tile
        {
            /// <summary>Bounding sphere of the tile's instances (local to this object).</summary>
            public Vector3 centre;
            public float radius;
            public float meanScale = 1f;
            public Matrix4x4[] matrices;
        }

        public LevelDraw[] levels;
        public Tile[] tiles;
        /// <summary>Beyond this (m, at scale 1, reference screen) nothing is drawn; 0: never culled.</summary>
        public float cullDistance;
        /// <summary>The reference screen verdant's distances are for ([lod] in the preset).</summary>
        public float referenceHeightPx = 1080f;
        public float referenceFovDeg = 60f;
        /// <summary>The camera drawn for; empty: Camera.main.</summary>
        public Camera viewCamera;

        const int Batch = 1023;
        Matrix4x4[] scratch = new Matrix4x4[Batch];

        /// <summary>verdant's distances hold on its reference screen: a camera with another field of
        /// view or height sees things larger or smaller by H / tan(fov/2) over the reference's.</summary>
        public float DistanceFactor(Camera cam)
        {
            float view = cam.pixelHeight / Mathf.Tan(cam.fieldOfView * Mathf.Deg2Rad * 0.5f);
            float reference = referenceHeightPx / Mathf.Tan(referenceFovDeg * Mathf.Deg2Rad * 0.5f);
            return view / reference;
        }

        /// <summary>The level a tile at this distance (m, from its nearest point) shows, -1: culled.</summary>
        public int LevelAt(float distance, Tile tile, float factor)
        {
            float d = distance / (tile.meanScale * factor);
            if (cullDistance > 0f && d > cullDistance) return -1;
            int level = 0;
            for (int k = 1; k < levels.Length; k++)
                if (levels[k].switchDistance <= d) level = k;
            return level;
        }

        void Update()
        {
            var cam = viewCamera != null ? viewCamera : Camera.main;
            if (cam == null || levels == null || tiles == null) return;
            float factor = DistanceFactor(cam);
            Matrix4x4 toWorld = transform.localToWorldMatrix;
            bool identity = toWorld == Matrix4x4.identity;
            foreach (var tile in tiles)
            {
                if (tile.matrices == null || tile.matrices.Length == 0) continue;
                Vector3 centre = toWorld.MultiplyPoint3x4(tile.centre);
                float distance = Mathf.Max(0f, Vector3.Distance(cam.transform.position, centre) - tile.radius);
                int k = LevelAt(distance, tile, factor);
                if (k < 0) continue;
                var level = levels[k];
                // the tile's instances inside: its sphere grown by the mesh (at twice the mean scale)
                float grow = level.mesh.bounds.extents.magnitude * tile.meanScale * 2f + level.mesh.bounds.center.magnitude;
                var bounds = new Bounds(centre, Vector3.one * 2f * (tile.radius + grow));
                for (int start = 0; start < tile.matrices.Length; start += Batch)
                {
                    int count = Mathf.Min(Batch, tile.matrices.Length - start);
                    for (int i = 0; i < count; i++)
                        scratch[i] = identity ? tile.matrices[start + i] : toWorld * tile.matrices[start + i];
                    for (int sub = 0; sub < level.mesh.subMeshCount && sub < level.materials.Length; sub++)
                    {
                        var rp = new RenderParams(level.materials[sub]) { worldBounds = bounds };
                        Graphics.RenderMeshInstanced(rp, level.mesh, sub, scratch, count);
                    }
                }
            }
        }
    }
}
