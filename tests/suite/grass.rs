//! Grass and flower species: byte-identical outputs at any thread count, every LoD a valid glb
//! that re-imports with its wind attributes, atlas mips that keep coverage, the analyzer's switch
//! distances ordered, the user's blade texture used, and the `[grass]`/`[flower]` preset tables
//! (defaults, overrides, positioned errors).

use std::path::Path;

use verdant::bake::atlas::coverage;
use verdant::bake::image::Image;
use verdant::export::gltf::to_glb;
use verdant::plants::flower::{build_flower, FlowerSettings};
use verdant::plants::grass::{GrassSettings, WIND_ATTRIBUTE};
use verdant::plants::grass_asset::{build_grass, GrassAsset};
use verdant::scene::preset::parse_preset;
use verdant::scene::PlantLook;

fn small() -> GrassSettings {
    GrassSettings { blades_per_clump: 24, density_levels: 2, variants: 2, atlas_px: 64, ..GrassSettings::default() }
}

fn bytes_of(a: &GrassAsset) -> Vec<Vec<u8>> {
    let mut out: Vec<Vec<u8>> = a.lod_scenes.iter().map(|s| to_glb(s).unwrap()).collect();
    out.push(to_glb(&a.chain).unwrap());
    out.push(to_glb(&a.far).unwrap());
    out.extend(a.atlas.iter().map(|m| m.image.encode_png().unwrap()));
    out.push(a.density_atlas.encode_png().unwrap());
    out
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(f)
}

#[test]
fn grass_outputs_are_byte_identical_at_one_and_two_threads() {
    let s = small();
    let one = in_pool(1, || build_grass("g", &s, None).unwrap());
    let two = in_pool(2, || build_grass("g", &s, None).unwrap());
    assert_eq!(bytes_of(&one), bytes_of(&two));
    assert_eq!(one.report.lods, two.report.lods, "the analyzer's figures too");
    let other = build_grass("g", &GrassSettings { seed: 5, ..s }, None).unwrap();
    assert_ne!(bytes_of(&one)[0], bytes_of(&other)[0], "another seed, other clumps");
}

#[test]
fn every_level_is_a_valid_glb_with_wind_and_fewer_triangles() {
    let dir = tempfile::tempdir().unwrap();
    let a = build_grass("g", &small(), None).unwrap();
    let mut last = usize::MAX;
    for (n, scene) in a.lod_scenes.iter().enumerate() {
        let path = dir.path().join(format!("g_LOD{n}.glb"));
        verdant::export::write_scene(scene, &path).unwrap();
        let report = verdant::validate::validate_file(&path, &Default::default()).unwrap();
        assert!(report.errors() == 0, "LOD{n}: {report:?}");
        let back = verdant::validate::read_scene(&path).unwrap();
        assert_eq!(back.meshes.len(), 4, "one mesh per clump");
        let tris: usize = back.meshes.iter().flat_map(|m| &m.primitives).map(|p| p.triangle_count()).sum();
        assert!(tris < last, "LOD{n}: {tris} triangles, not fewer than {last}");
        last = tris;
        for p in back.meshes.iter().flat_map(|m| &m.primitives) {
            assert_eq!(p.custom.len(), 1);
            assert_eq!(p.custom[0].name, WIND_ATTRIBUTE);
            assert_eq!(p.custom[0].values.len(), p.positions.len());
            // no COLOR_0: glTF would multiply it into the blade's colour and alpha
            assert!(p.colors.is_empty(), "LOD{n}: grass with COLOR_0");
        }
        assert_eq!(back.meshes, scene.meshes, "LOD{n} re-imports equal to what was written");
    }
    // the chain: LoD0 roots with MSFT_lod to the other levels, coverages never increasing
    let chain_path = dir.path().join("g.glb");
    verdant::export::write_scene(&a.chain, &chain_path).unwrap();
    let chain = verdant::validate::read_scene(&chain_path).unwrap();
    for &r in &chain.roots {
        let node = &chain.nodes[r];
        assert_eq!(node.lods.len(), 3);
        assert_eq!(node.lod_screen_coverage.len(), 4);
        assert!(node.lod_screen_coverage.windows(2).all(|w| w[0] >= w[1]), "{:?}", node.lod_screen_coverage);
    }
}

#[test]
fn analyzer_orders_switch_distances_and_mips_keep_coverage() {
    let a = build_grass("g", &GrassSettings::default(), None).unwrap();
    let lods = &a.report.lods;
    assert_eq!(lods[0].switch_distance_m, 0.0);
    for w in lods.windows(2) {
        assert!(
            w[1].switch_distance_m >= w[0].switch_distance_m,
            "{} then {}",
            w[0].switch_distance_m,
            w[1].switch_distance_m
        );
    }
    // the coarse levels do switch within the measured range, and not at the viewer's feet
    for l in &lods[1..] {
        assert!(!l.never_passes, "LOD{} never passes", l.level);
        assert!((4.0..256.0).contains(&l.switch_distance_m), "LOD{} switches at {} m", l.level, l.switch_distance_m);
        assert!(!l.measured.is_empty() && l.measured.iter().any(|m| m.passes) && l.measured.iter().any(|m| !m.passes));
    }
    let c0 = a.atlas[0].coverage;
    for (k, m) in a.atlas.iter().enumerate().filter(|(_, m)| m.image.width.min(m.image.height) >= 16) {
        assert!((m.coverage / c0 - 1.0).abs() <= 0.02, "atlas mip {k}: coverage {} vs {c0}", m.coverage);
        assert_eq!(coverage(&m.image, a.settings.alpha_cutoff), m.coverage);
    }
    // the density atlas: alpha 0 where the atlas is transparent, ranks spread over (0, 1] elsewhere
    let ranks: Vec<f32> = a.density_atlas.pixels.iter().map(|p| p[3]).filter(|&x| x > 0.0).collect();
    assert!(ranks.len() > 1000);
    let (lo, hi) = ranks.iter().fold((1.0f32, 0.0f32), |(l, h), &x| (l.min(x), h.max(x)));
    assert!(lo < 0.2 && hi > 0.8, "ranks span {lo}..{hi}");
}

#[test]
fn a_user_blade_texture_replaces_the_procedural_one() {
    // a plain red blade, opaque in the middle half of the width
    let mut user = Image::new(8, 32, [0.0; 4]).unwrap();
    for y in 0..32 {
        for x in 2..6 {
            user.pixels[y * 8 + x] = [0.8, 0.05, 0.05, 1.0];
        }
    }
    let s = GrassSettings { value_jitter: 0.0, hue_jitter: 0.0, ..small() };
    let a = build_grass("g", &s, Some(&user)).unwrap();
    let blade = &a.blade[0].image;
    let opaque: Vec<&[f32; 4]> = blade.pixels.iter().filter(|p| p[3] >= 0.99).collect();
    assert!(!opaque.is_empty());
    assert!(opaque.iter().all(|p| p[0] > 0.5 && p[1] < 0.2), "the user's red, not the procedural green");
}

#[test]
fn flowers_are_crossed_billboards_of_a_baked_flower() {
    let s = FlowerSettings::default();
    let a = build_flower("f", &s).unwrap();
    assert_eq!(a.scene.meshes.len(), s.variants);
    assert!(a.scene.meshes.iter().all(|m| m.primitives[0].triangle_count() == 4));
    // every variant's atlas cell has colour (petals) and transparency (around the flower)
    let img = &a.atlas[0].image;
    let cell_w = img.width / s.variants as u32;
    for v in 0..s.variants as u32 {
        let cell: Vec<[f32; 4]> = (0..img.height)
            .flat_map(|y| (0..cell_w).map(move |x| (x, y)))
            .map(|(x, y)| img.pixels[(y * img.width + v * cell_w + x) as usize])
            .collect();
        let covered = cell.iter().filter(|p| p[3] >= s.alpha_cutoff).count();
        assert!(covered > 50 && covered < cell.len() / 2, "variant {v}: {covered} covered texels");
        assert!(
            cell.iter().any(|p| p[3] >= s.alpha_cutoff && p[0] > 0.4 && p[1] < 0.3),
            "variant {v}: no petal colour"
        );
    }
    let again = build_flower("f", &s).unwrap();
    assert_eq!(to_glb(&a.scene).unwrap(), to_glb(&again.scene).unwrap());
}

const BASE: &str = "[scene]\nname = \"m\"\n[terrain]\nprocedural = { kind = \"fbm\", size = 65, relief = 10.0 }\n";

fn look_of(text: &str, species: usize) -> PlantLook {
    parse_preset(text, Path::new("p.toml")).unwrap().species[species].look.clone()
}

fn error_of(text: &str) -> String {
    match parse_preset(text, Path::new("p.toml")) {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn grass_and_flower_tables_set_defaults_and_species_override_them() {
    let text = format!(
        "{BASE}[grass]\nsegments = 4\nheight = [0.1, 0.2]\nroot_color = \"#000000\"\n\
         [flower]\npetals = 5\n\
         [[species]]\nname = \"a\"\nkind = \"grass\"\nmax_density = 1.0\n\
         [[species]]\nname = \"b\"\nkind = \"grass\"\nmax_density = 1.0\ngrass = {{ segments = 3, bend = [0.0, 45.0] }}\n\
         [[species]]\nname = \"c\"\nkind = \"flower\"\nmax_density = 0.1\nflower = {{ petal_color = [1.0, 1.0, 1.0] }}\n\
         [[species]]\nname = \"d\"\nkind = \"tree\"\nmax_density = 0.01\n"
    );
    let PlantLook::Grass(a) = look_of(&text, 0) else { panic!() };
    assert_eq!((a.segments, a.height_m, a.root_color), (4, [0.1, 0.2], [0.0; 3]));
    let PlantLook::Grass(b) = look_of(&text, 1) else { panic!() };
    assert_eq!(b.segments, 3, "the species' own table wins");
    assert_eq!(b.height_m, [0.1, 0.2], "unset keys keep [grass]'s");
    assert!((b.bend_rad[1] - 45f32.to_radians()).abs() < 1e-6, "bend is given in degrees");
    assert_ne!(a.seed, b.seed, "each species has its own seed");
    let PlantLook::Flower(c) = look_of(&text, 2) else { panic!() };
    assert_eq!((c.petals, c.petal_color), (5, [1.0, 1.0, 1.0]));
    // a tree species without an L-system grows a built-in tree, not a marker
    assert!(
        matches!(look_of(&text, 3), PlantLook::Tree(t) if t.lsystem.as_path() == std::path::Path::new("builtin:broadleaf"))
    );
    // no tables: the defaults
    let plain = format!("{BASE}[[species]]\nname = \"g\"\nkind = \"grass\"\nmax_density = 1.0\n");
    let PlantLook::Grass(g) = look_of(&plain, 0) else { panic!() };
    assert_eq!(GrassSettings { seed: 0, ..g }, GrassSettings::default());
}

#[test]
fn grass_mistakes_are_positioned_errors() {
    let species = "[[species]]\nname = \"g\"\nkind = \"grass\"\nmax_density = 1.0\n";
    let e = error_of(&format!("{BASE}{species}grass = {{ segmnts = 4 }}\n"));
    assert!(e.starts_with("p.toml:9:11") && e.contains("`segments`"), "{e}");
    let e = error_of(&format!("{BASE}[grass]\nheight = [0.5, 0.1]\n"));
    assert!(e.starts_with("p.toml:6:") && e.contains("min, max"), "{e}");
    let e = error_of(&format!("{BASE}[grass]\nroot_color = \"#12345\"\n"));
    assert!(e.starts_with("p.toml:6:") && e.contains("six hex digits"), "{e}");
    let e = error_of(&format!("{BASE}[grass]\nblades = 6\n"));
    assert!(e.contains("blades_per_clump") && e.contains("18"), "{e}");
    let e = error_of(&format!(
        "{BASE}[[species]]\nname = \"t\"\nkind = \"tree\"\nmax_density = 0.1\ngrass = {{ segments = 4 }}\n"
    ));
    assert!(e.starts_with("p.toml:9:1") && e.contains("kind = \"grass\""), "{e}");
    // input files are checked when a preset is loaded from disk
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.toml");
    std::fs::write(&path, format!("{BASE}{species}grass = {{ blade_texture = \"missing.png\" }}\n")).unwrap();
    let e = verdant::scene::preset::load_preset(&path).unwrap_err().to_string();
    assert!(e.contains("missing.png") && e.contains(":9:"), "{e}");
    let e = error_of(&format!("{BASE}[flower]\npetals = 2\n"));
    assert!(e.starts_with("p.toml:6:") && e.contains("petals"), "{e}");
}
