//! Wind data engines can read (docs/wind.md): every plant vertex has `_WIND` (bend weight, phase,
//! frequency, stiffness) and L-system trees `_WIND_BRANCH` (branch weight, limb phase, flutter,
//! flutter phase); COLOR_0 is only ever a real colour (alpha 1). The old grass kept wind data in
//! COLOR_0, which glTF multiplies into the base colour and alpha: black, cut-out grass.
//!
//! [`check_plant_scene`] is run on every shipped species by `atlas_cells` (which builds them all).

use std::f32::consts::TAU;
use std::path::Path;

use verdant::lsystem::parse::parse_bytes;
use verdant::mesh::{Mesh, Primitive, Scene};
use verdant::plants::tree::{build_tree, TreeOptions};
use verdant::plants::wind::{find, WIND_ATTRIBUTE, WIND_BRANCH_ATTRIBUTE};

/// What a plant file is expected to carry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Expect {
    /// `_WIND` on every primitive.
    Sway,
    /// `_WIND` everywhere and `_WIND_BRANCH` on every primitive of the full-detail tree.
    SwayAndBranch,
    /// No wind data (a rock).
    Nothing,
}

fn wind_of<'a>(what: &str, p: &'a Primitive, name: &str) -> &'a [[f32; 4]] {
    let a = find(&p.custom, name).unwrap_or_else(|| panic!("{what}: a primitive without {name}"));
    assert_eq!(a.values.len(), p.positions.len(), "{what}: {name} has one value per vertex");
    &a.values
}

/// COLOR_0 only as a colour, `_WIND` within its documented ranges with a bend weight that grows
/// with height, `_WIND_BRANCH` where expected; returns the vertices checked.
pub fn check_plant_scene(what: &str, scene: &Scene, expect: Expect) -> usize {
    let mut checked = 0;
    for mesh in &scene.meshes {
        let what = format!("{what} mesh {}", mesh.name);
        for p in &mesh.primitives {
            assert!(
                p.colors.iter().all(|c| c[3] == 1.0 && c.iter().all(|x| (0.0..=1.0).contains(x))),
                "{what}: COLOR_0 that is not an opaque colour"
            );
            if expect == Expect::Nothing {
                assert!(find(&p.custom, WIND_ATTRIBUTE).is_none(), "{what}: wind data on a model that does not sway");
                continue;
            }
            for v in wind_of(&what, p, WIND_ATTRIBUTE) {
                assert!((0.0..=1.0).contains(&v[0]), "{what}: bend weight {}", v[0]);
                assert!((0.0..TAU).contains(&v[1]), "{what}: phase {}", v[1]);
                assert!(v[2] > 0.0 && v[2] <= 4.0, "{what}: frequency {} Hz", v[2]);
                assert!((0.0..=1.0).contains(&v[3]), "{what}: stiffness {}", v[3]);
            }
            checked += p.positions.len();
        }
        if expect != Expect::Nothing {
            bend_grows_with_height(&what, mesh);
        }
        if expect == Expect::SwayAndBranch {
            check_branch(&what, mesh);
        }
    }
    checked
}

/// Across a mesh the bend weight is one non-decreasing function of height: 0 at the ground and
/// (for a mesh reaching its plant's top) 1 there.
fn bend_grows_with_height(what: &str, mesh: &Mesh) {
    let mut pairs: Vec<(f32, f32)> = mesh
        .primitives
        .iter()
        .flat_map(|p| p.positions.iter().zip(wind_of(what, p, WIND_ATTRIBUTE)).map(|(q, w)| (q[1], w[0])))
        .collect();
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    for w in pairs.windows(2) {
        assert!(
            w[1].1 >= w[0].1 - 1e-6,
            "{what}: bend weight {} at y = {} but {} at y = {}",
            w[0].1,
            w[0].0,
            w[1].1,
            w[1].0
        );
    }
    let lowest = pairs.first().expect("a mesh with vertices");
    if lowest.0 <= 1e-6 {
        assert!(lowest.1 <= 1e-6, "{what}: the ground bends ({})", lowest.1);
    }
}

/// Branch weights 0..1 reaching 1, 0 on the trunk; flutter only on leaves.
fn check_branch(what: &str, mesh: &Mesh) {
    let mut max_weight = 0.0f32;
    for p in &mesh.primitives {
        for v in wind_of(what, p, WIND_BRANCH_ATTRIBUTE) {
            assert!(
                (0.0..=1.0).contains(&v[0]) && (0.0..=1.0).contains(&v[2]),
                "{what}: branch weight {} flutter {}",
                v[0],
                v[2]
            );
            assert!((0.0..TAU).contains(&v[1]) && (0.0..TAU).contains(&v[3]), "{what}: phases {} {}", v[1], v[3]);
            max_weight = max_weight.max(v[0]);
        }
    }
    assert!(max_weight > 0.99, "{what}: the farthest tip has branch weight {max_weight}, not 1");
}

fn system(text: &str) -> verdant::lsystem::LSystem {
    parse_bytes(text.as_bytes(), Path::new("wind.ls"), None).unwrap_or_else(|e| panic!("{e}")).system
}

#[test]
fn a_limb_bends_from_its_joint_and_its_twig_continues_it() {
    // trunk F, limb 1 = [+F [-F] F] with a twig, the trunk again and limb 2 = [&FF]
    let tree =
        build_tree(&system("recursion 0\nangle 30\nthickness 10\naxiom F[+F[-F]F]F[&FF]\n"), &TreeOptions::default())
            .unwrap();
    let mesh = tree.mesh();
    check_plant_scene("tree", &tree.scene, Expect::SwayAndBranch);
    let p = &mesh.primitives[0];
    let branch = wind_of("tree", p, WIND_BRANCH_ATTRIBUTE);
    let ranges = &tree.levels[0];
    let trunk_end = ranges.vertex_starts.get(1).map_or(p.positions.len(), |&v| v as usize);
    // the trunk (level 0) holds still under branch bending, sways with the whole tree
    assert!(branch[..trunk_end].iter().all(|v| v[0] == 0.0 && v[1] == 0.0), "trunk vertices bend with a branch");
    // where a limb leaves the trunk its weight is 0: the joint does not tear whatever the limb's phase
    let lowest_on_limbs = branch[trunk_end..].iter().map(|v| v[0]).fold(f32::MAX, f32::min);
    assert_eq!(lowest_on_limbs, 0.0);
    // two limbs, two phases; the twig on limb 1 shares its phase
    let mut phases: Vec<u32> = branch[trunk_end..].iter().map(|v| v[1].to_bits()).collect();
    phases.sort_unstable();
    phases.dedup();
    assert_eq!(phases.len(), 2, "one phase per limb");
    // the tree's top (the trunk's tip at y = 2 steps) has bend weight 1, its root 0
    let sway = wind_of("tree", p, WIND_ATTRIBUTE);
    let top = p.positions.iter().map(|q| q[1]).fold(f32::MIN, f32::max);
    for (q, w) in p.positions.iter().zip(sway) {
        assert!((w[0] - (q[1] / top).clamp(0.0, 1.0).powi(2)).abs() < 1e-5, "bend at y = {}: {}", q[1], w[0]);
    }
    // the same tree twice: the same wind data (seeded, order-independent)
    let again =
        build_tree(&system("recursion 0\nangle 30\nthickness 10\naxiom F[+F[-F]F]F[&FF]\n"), &TreeOptions::default())
            .unwrap();
    assert_eq!(again.mesh(), mesh);
}

#[test]
fn leaves_flutter_at_the_tip_and_hold_at_the_stalk() {
    // the thesis dialect's `L` leaves: quads whose stalk corners hold still
    let text = "1-1\n30\n18\nX(100)=F[+FL]F[-FL]AL\nA(100)=F\n@\n";
    let parsed = parse_bytes(text.as_bytes(), Path::new("leaves.ls"), None).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(parsed.system.dialect, verdant::lsystem::Dialect::Stochastic);
    let tree = build_tree(&parsed.system, &TreeOptions::default()).unwrap();
    let mut leaf_vertices = 0;
    for p in &tree.mesh().primitives {
        let branch = wind_of("leaves", p, WIND_BRANCH_ATTRIBUTE);
        let leafy = p.uvs.len() == p.positions.len() && branch.iter().any(|v| v[2] > 0.0);
        if !leafy {
            assert!(branch.iter().all(|v| v[2] == 0.0), "wood flutters");
            continue;
        }
        for (uv, v) in p.uvs.iter().zip(branch) {
            // leaf quads: v = 1 at the stalk, 0 at the tip
            assert_eq!(v[2], if uv[1] == 0.0 { 1.0 } else { 0.0 });
            leaf_vertices += 1;
        }
    }
    assert!(leaf_vertices >= 12, "{leaf_vertices} leaf vertices");
}

#[test]
fn polygon_leaves_flutter_away_from_their_stalk() {
    // lparser polygons: held at their first vertex (where `{` was), fluttering most at the far edge
    let tree =
        build_tree(&system("recursion 0\nangle 30\nthickness 10\naxiom F[+F{.f.+f.+f.}]\n"), &TreeOptions::default())
            .unwrap();
    let mut polygon_vertices = 0;
    for p in &tree.mesh().primitives {
        let branch = wind_of("polygons", p, WIND_BRANCH_ATTRIBUTE);
        if branch.iter().all(|v| v[2] == 0.0) {
            continue;
        }
        assert!(branch.iter().any(|v| v[2] == 0.0) && branch.iter().any(|v| v[2] == 1.0), "{branch:?}");
        polygon_vertices += p.positions.len();
    }
    assert!(polygon_vertices >= 3);
}

#[test]
fn wind_survives_the_written_file() {
    let tree =
        build_tree(&system("recursion 0\nangle 30\nthickness 10\naxiom F[+F[-F]F]F[&FF]\n"), &TreeOptions::default())
            .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.glb");
    verdant::export::write_scene(&tree.scene, &path).unwrap();
    let back = verdant::validate::read_scene(&path).unwrap();
    assert_eq!(back.meshes, tree.scene.meshes);
    // the accessors carry the documented names, VEC4 float
    let bytes = std::fs::read(&path).unwrap();
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let json: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let prim = &json["meshes"][0]["primitives"][0];
    for name in [WIND_ATTRIBUTE, WIND_BRANCH_ATTRIBUTE] {
        let a = prim["attributes"][name].as_u64().unwrap_or_else(|| panic!("no {name}")) as usize;
        assert_eq!(json["accessors"][a]["type"], "VEC4");
        assert_eq!(json["accessors"][a]["componentType"], 5126);
    }
    assert!(prim["attributes"].get("COLOR_0").is_none());
}
