// MSFT_lod for three.js: a GLTFLoader plugin that turns every node with the MSFT_lod extension
// into a ScreenCoverageLOD, which shows the level the node's extras.MSFT_screencoverage asks for,
// computed as Babylon.js computes it (the bounding sphere's projected disc over the screen's area).
// three.js itself ignores MSFT_lod and shows only the full-detail node; verdant's chains (grass.glb,
// tree and mesh chains) carry every level in the one file, so nothing more is fetched.
//
//   import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
//   import { MSFTLodPlugin } from './three_msft_lod.js';
//   const loader = new GLTFLoader().register((parser) => new MSFTLodPlugin(parser));
//   const gltf = await loader.loadAsync('tree.glb');  // each chain node is now a ScreenCoverageLOD
//
// The LOD picks its level every frame in the renderer (autoUpdate), from the camera it is drawn
// with: level k is shown while the coverage is at least coverage[k] (the last is 0, so the coarsest
// level is never culled); a node without MSFT_screencoverage gets coverages halving from 1/2 per
// level. A camera inside the bounding sphere sees level 0.
import { Box3, LOD, Sphere, Vector3 } from 'three';

const _centre = new Vector3();
const _eye = new Vector3();
const _box = new Box3();
const _sphere = new Sphere();

// The fraction of the screen the sphere (world centre, radius) covers seen from `camera`: π r² over
// the screen's area at the sphere's distance (a perspective camera's view is 2·D·tan(fov/2) high,
// `aspect` times as wide; an orthographic camera's is its frustum over its zoom).
export function screenCoverage(camera, centre, radius) {
  if (camera.isOrthographicCamera) {
    const w = (camera.right - camera.left) / camera.zoom;
    const h = (camera.top - camera.bottom) / camera.zoom;
    return Math.min(1, (Math.PI * radius * radius) / Math.abs(w * h));
  }
  _eye.setFromMatrixPosition(camera.matrixWorld);
  const d = _eye.distanceTo(centre);
  if (d <= radius) return 1;
  const h = (2 * d * Math.tan((camera.fov * Math.PI) / 360)) / camera.zoom;
  return Math.min(1, (Math.PI * radius * radius) / (camera.aspect * h * h));
}

// A THREE.LOD whose levels switch on screen coverage (MSFT_screencoverage) rather than distance.
// `levels[k].coverage` is the smallest coverage at which level k is shown; the bounding sphere is
// level 0's, in the LOD's own space (scaled with it).
export class ScreenCoverageLOD extends LOD {
  constructor(centre = new Vector3(), radius = 0) {
    super();
    this.type = 'ScreenCoverageLOD';
    this.centre = centre.clone();
    this.radius = radius;
  }

  addCoverageLevel(object, coverage) {
    // the parent class keeps levels sorted by `distance`: the level's place in the chain
    this.addLevel(object, this.levels.length);
    this.levels[this.levels.length - 1].coverage = coverage;
    return this;
  }

  // The level for `camera`, without changing what is shown.
  levelFor(camera) {
    _centre.copy(this.centre).applyMatrix4(this.matrixWorld);
    const coverage = screenCoverage(camera, _centre, this.radius * this.matrixWorld.getMaxScaleOnAxis());
    const last = this.levels.length - 1;
    for (let k = 0; k < last; k++) if (coverage >= this.levels[k].coverage) return k;
    return last;
  }

  update(camera) {
    if (this.levels.length === 0) return;
    const shown = this.levelFor(camera);
    this.levels.forEach((level, k) => { level.object.visible = k === shown; });
    this._currentLevel = shown;
  }

  getObjectForDistance() {
    return this.levels[this._currentLevel]?.object ?? null;
  }

  raycast(raycaster, intersects) {
    this.getObjectForDistance()?.raycast(raycaster, intersects);
  }

  copy(source) {
    super.copy(source);
    this.centre.copy(source.centre);
    this.radius = source.radius;
    this.levels.forEach((level, k) => { level.coverage = source.levels[k].coverage; });
    return this;
  }
}

export class MSFTLodPlugin {
  constructor(parser) {
    this.parser = parser;
    this.name = 'MSFT_lod';
  }

  async afterRoot(gltf) {
    const json = this.parser.json;
    const nodes = json.nodes ?? [];
    for (let index = 0; index < nodes.length; index++) {
      const ids = nodes[index].extensions?.MSFT_lod?.ids;
      if (!Array.isArray(ids) || ids.length === 0) continue;
      const base = await this.parser.getDependency('node', index);
      const levels = [base, ...(await Promise.all(ids.map((id) => this.parser.getDependency('node', id))))];
      const given = nodes[index].extras?.MSFT_screencoverage;
      const coverage = levels.map((_, k) =>
        Array.isArray(given) && Number.isFinite(given[k]) ? given[k] : k === levels.length - 1 ? 0 : 0.5 ** (k + 1));
      // MSFT_lod levels are alternatives for the node in its parent: each keeps its own transform
      // (verdant repeats the node's), and the LOD stands in the node's place at the identity. The
      // bounding sphere is level 0's, in the parent's space.
      const parent = base.parent;
      base.updateMatrixWorld(true);
      const toParent = parent ? parent.matrixWorld.clone().invert() : base.matrixWorld.clone().identity();
      _box.makeEmpty();
      base.traverse((o) => {
        if (o.isInstancedMesh) {
          // EXT_mesh_gpu_instancing: the box around every instance, not one copy at the origin
          o.computeBoundingBox();
          _box.union(o.boundingBox.clone().applyMatrix4(toParent.clone().multiply(o.matrixWorld)));
        } else if (o.isMesh && o.geometry) {
          if (!o.geometry.boundingBox) o.geometry.computeBoundingBox();
          _box.union(o.geometry.boundingBox.clone().applyMatrix4(toParent.clone().multiply(o.matrixWorld)));
        }
      });
      _box.getBoundingSphere(_sphere);
      const lod = new ScreenCoverageLOD(_sphere.center, _box.isEmpty() ? 0 : _sphere.radius);
      lod.name = base.name;
      lod.userData = { ...base.userData, MSFT_lod: { ids, coverage } };
      const place = parent ? parent.children.indexOf(base) : -1;
      levels.forEach((object, k) => {
        object.removeFromParent();
        lod.addCoverageLevel(object, coverage[k]);
      });
      if (parent) {
        parent.add(lod);
        parent.children.splice(parent.children.length - 1, 1);
        parent.children.splice(place, 0, lod);
      }
      // (the levels leave their own scene: verdant keeps them in a second, non-default one)
      this.parser.associations?.set(lod, { nodes: index });
    }
  }
}
