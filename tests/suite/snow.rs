//! Snow through the public API: the flake atlas (habits by temperature, six-fold symmetry), the
//! emitter's physics, the particle frame's volume, the terrain cover's slope rule, the written glb
//! files, determinism across thread counts and the errors bad settings give.

use verdant::bake::image::Image;
use verdant::export::write_scene;
use verdant::mesh::Scene;
use verdant::snow::emitter::GRAVITY_M_S2;
use verdant::snow::*;
use verdant::terrain::build::{build_scene, BuildOptions};
use verdant::terrain::grid::grid;
use verdant::validate::{read_scene, validate_file, ValidateOptions};

fn with_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(f)
}

/// Relative alpha mismatch of `img` and itself turned by `deg` about its centre, inside the
/// inscribed circle: Σ|a(p) − a(R·p)| / Σ a(p).
fn rotation_mismatch(img: &Image, deg: f32) -> f64 {
    let n = img.width as f32;
    let c = n / 2.0;
    let (s, co) = deg.to_radians().sin_cos();
    let (mut diff, mut total) = (0.0f64, 0.0f64);
    for y in 0..img.height {
        for x in 0..img.width {
            let (dx, dy) = (x as f32 + 0.5 - c, y as f32 + 0.5 - c);
            if dx * dx + dy * dy > (c - 1.0) * (c - 1.0) {
                continue;
            }
            let (rx, ry) = (c + co * dx - s * dy, c + s * dx + co * dy);
            let a = img.pixel(x, y).unwrap()[3] as f64;
            let b = img.sample_bilinear([rx / n, ry / n])[3] as f64;
            diff += (a - b).abs();
            total += a;
        }
    }
    diff / total.max(1e-9)
}

fn atlas_px(temperature_c: f32, humidity: f32, cell_px: u32) -> FlakeAtlas {
    build_atlas(&FlakeSettings { temperature_c, humidity, columns: 4, rows: 4, cell_px, ..FlakeSettings::default() })
        .unwrap()
}

fn atlas_at(temperature_c: f32, humidity: f32) -> FlakeAtlas {
    atlas_px(temperature_c, humidity, 64)
}

#[test]
fn atlas_cells_are_filled_and_rotationally_symmetric() {
    // aggregates (random clusters near 0 °C) have no symmetry and are left out; needles and
    // columns are prisms seen side-on, checked at 180°; every other habit at 60°. At 128 px a cell
    // the mismatch left is edge anti-aliasing of arms a few pixels wide (measured up to 0.11).
    let mut checked = [0usize; 2];
    let mut outlines = std::collections::HashSet::new();
    for t in [-6.0, -10.0, -15.0, -21.0, -32.0] {
        let atlas = atlas_px(t, 0.7, 128);
        assert_eq!(atlas.image.width, 4 * 128);
        assert_eq!(atlas.cells.len(), 16);
        // anti-aliased (resolved from 2×): edge texels are partly covered (an axis-aligned column
        // edge can fall between samples, so this is asked of the atlas, not of every cell)
        let partial = atlas.image.pixels.iter().filter(|p| p[3] > 0.05 && p[3] < 0.95).count();
        assert!(partial > 100, "{t} °C: {partial} partly covered texels");
        for cell in &atlas.cells {
            let img = atlas.cell_image(cell.index);
            let covered = img.pixels.iter().filter(|p| p[3] >= 0.5).count();
            assert!(
                covered as f64 > 0.02 * img.pixels.len() as f64,
                "cell {} ({:?}) at {t} °C covers {covered} px",
                cell.index,
                cell.kind
            );
            outlines.insert((cell.kind, covered));
            let Some(angle) = cell.kind.symmetry_deg() else { continue };
            let e = rotation_mismatch(&img, angle);
            assert!(e < 0.15, "cell {} ({:?}) at {t} °C: {angle}° mismatch {e:.3}", cell.index, cell.kind);
            // the measure can tell: turning by half the symmetry angle does not match
            let off = rotation_mismatch(&img, angle / 2.0);
            assert!(
                off > 2.0 * e + 0.05,
                "cell {} ({:?}): {angle}° {e:.3}, {}° {off:.3}",
                cell.index,
                cell.kind,
                angle / 2.0
            );
            checked[(angle > 90.0) as usize] += 1;
        }
    }
    assert!(checked[0] >= 40 && checked[1] >= 25, "{checked:?}");
    // per-flake variation shows in the outline, not only the shading: of 80 cells most differ
    assert!(outlines.len() > 60, "{} distinct outlines", outlines.len());
}

#[test]
fn habits_and_sizes_follow_temperature_and_humidity() {
    let count = |a: &FlakeAtlas, k: FlakeKind| a.cells.iter().filter(|c| c.kind == k).count();
    for (t, kind) in [
        (-6.0, FlakeKind::Needle),
        (-10.0, FlakeKind::Plate),
        (-15.0, FlakeKind::StellarDendrite),
        (-21.5, FlakeKind::SpatialDendrite),
        (-33.0, FlakeKind::Column),
        (0.0, FlakeKind::Aggregate),
    ] {
        let a = atlas_at(t, 0.7);
        assert!(count(&a, kind) >= 12, "{t} °C: {:?}", a.cells.iter().map(|c| c.kind).collect::<Vec<_>>());
    }
    // dry air at −15 °C grows plates, not dendrites
    assert!(count(&atlas_at(-15.0, 0.1), FlakeKind::Plate) >= 12);
    let mean = |a: &FlakeAtlas| a.cells.iter().map(|c| c.size_mm).sum::<f32>() / a.cells.len() as f32;
    assert!(mean(&atlas_at(0.0, 0.7)) > 2.0 * mean(&atlas_at(-15.0, 0.7)), "aggregates near 0 °C are the large flakes");
    assert!(mean(&atlas_at(-15.0, 0.9)) > mean(&atlas_at(-15.0, 0.3)), "wetter air grows larger crystals");
}

#[test]
fn terminal_velocity_is_m_g_over_k_and_a_fall_converges_to_it() {
    let e = Emitter { flake_mass_kg: 2.0e-6, drag_kg_s: 4.0e-5, ..Emitter::default() };
    let expected = 2.0e-6 * GRAVITY_M_S2 / 4.0e-5;
    assert!((e.terminal_velocity_m_s() - expected).abs() < 1e-6);
    assert!((Emitter::default().terminal_velocity_m_s() - 0.98).abs() < 0.01, "defaults fall at ~1 m/s");
    // from rest, Euler steps of 1 ms for ten time constants
    let (dt, mut v, mut t) = (1e-3, 0.0f32, 0.0f32);
    while t < 10.0 * e.time_constant_s() {
        let next = e.step_fall_speed(v, dt);
        assert!(next >= v && next <= expected * 1.0001, "speeds up monotonically, never past terminal");
        v = next;
        t += dt;
    }
    assert!((v - expected).abs() < 1e-3 * expected, "{v} vs {expected}");
    // after one time constant, 1 − 1/e of terminal (analytic solution)
    let (mut v1, mut t1) = (0.0f32, 0.0f32);
    while t1 < e.time_constant_s() {
        v1 = e.step_fall_speed(v1, 1e-4);
        t1 += 1e-4;
    }
    assert!((v1 / expected - (1.0 - (-1.0f32).exp())).abs() < 0.01, "{}", v1 / expected);
    // ground slow-down: full speed above the band, the factor at the ground, monotone between
    assert_eq!(e.ground_factor(e.ground_slowdown_m + 0.1), 1.0);
    assert!((e.ground_factor(0.0) - e.ground_speed_factor).abs() < 1e-6);
    assert!(e.ground_factor(0.1) < e.ground_factor(0.3));
}

#[test]
fn particles_lie_inside_the_declared_volume() {
    let atlas = atlas_at(-15.0, 0.6);
    let e = Emitter::default();
    let far = e.far.clone().unwrap();
    let ps = particles(&e, &atlas).unwrap();
    assert_eq!(ps.len(), (e.near_count + far.count) as usize);
    let half = far.view_angle_deg.to_radians() / 2.0;
    let mut inner_half = 0;
    for p in &ps {
        let [x, y, z] = p.position;
        let r = (x * x + z * z).sqrt();
        assert!((0.0..=e.fall_height_m).contains(&y), "{p:?}");
        match p.field {
            Field::Near => {
                assert!(r <= e.near_radius_m * 1.0001, "{p:?}");
                inner_half += (r < e.near_radius_m / 2f32.sqrt()) as usize;
            }
            Field::Far => {
                assert!(r >= e.near_radius_m * 0.9999 && r <= far.outer_radius_m * 1.0001, "{p:?}");
                // angle from straight ahead (−Z)
                assert!(x.atan2(-z).abs() <= half + 1e-4, "{p:?} outside the view angle");
            }
        }
        assert!(p.cell < atlas.cells.len());
        assert!(p.size_m > 0.0 && p.size_m < 0.05);
        assert!(p.spin_rad_s.abs() <= e.max_spin_rad_s);
    }
    // area-uniform in the disc: half the near flakes inside r1/√2
    let frac = inner_half as f64 / e.near_count as f64;
    assert!((frac - 0.5).abs() < 0.03, "{frac}");
    let csv = particles_csv(&ps);
    assert_eq!(csv.lines().count(), ps.len() + 1);
    assert!(csv.starts_with("field,x,y,z,size_m,cell,angle_rad,spin_rad_s\n"));
    // without a far field only the cylinder is filled
    let near_only = particles(&Emitter { far: None, ..e.clone() }, &atlas).unwrap();
    assert_eq!(near_only.len(), e.near_count as usize);
}

fn terrain() -> Scene {
    let hf = verdant::synth::fractal(65, 65, 2.0, 60.0, 0.55, 5);
    let mesh = grid(&hf, 1).unwrap();
    build_scene(&hf, &mesh, &BuildOptions::default()).unwrap()
}

#[test]
fn snow_weight_never_increases_with_slope() {
    let s = CoverSettings { snow_line_m: 20.0, snow_line_noise_m: 5.0, wind_scour: 0.7, ..CoverSettings::default() };
    for altitude in [0.0, 15.0, 20.0, 25.0, 60.0] {
        for aspect in (0..24).map(|k| k as f32 * 15f32.to_radians()) {
            let mut last = f32::INFINITY;
            for step in 0..=180 {
                let slope = (step as f32 * 0.5).to_radians();
                let n = [slope.sin() * aspect.cos(), slope.cos(), slope.sin() * aspect.sin()];
                let [w, _, _] = snow_weight(&s, [13.0, altitude, -7.0], n);
                assert!((0.0..=1.0).contains(&w));
                assert!(
                    w <= last + 1e-6,
                    "altitude {altitude}, aspect {aspect}: {w} after {last} at slope {}",
                    step as f32 * 0.5
                );
                last = w;
            }
        }
    }
    // flat ground well above the line is fully covered, a cliff bare, ground well below bare
    assert_eq!(snow_weight(&s, [0.0, 60.0, 0.0], [0.0, 1.0, 0.0])[0], 1.0);
    assert_eq!(snow_weight(&s, [0.0, 60.0, 0.0], [0.8660254, 0.5, 0.0])[0], 0.0);
    assert_eq!(snow_weight(&s, [0.0, 0.0, 0.0], [0.0, 1.0, 0.0])[0], 0.0);
    // a face turned into the wind holds less than its lee twin
    let into = snow_weight(&s, [0.0, 60.0, 0.0], [-0.3, 0.954, 0.0])[0];
    let lee = snow_weight(&s, [0.0, 60.0, 0.0], [0.3, 0.954, 0.0])[0];
    assert!(into < lee, "{into} vs {lee}");
}

#[test]
fn cover_on_a_terrain_attribute_mask_layer_and_report() {
    let mut scene = terrain();
    // snow line below the whole terrain and no wind: the weight depends on slope alone
    let s = CoverSettings { snow_line_m: -100.0, wind_scour: 0.0, ..CoverSettings::default() };
    apply_cover(&mut scene, &s).unwrap();
    for p in scene.meshes.iter().flat_map(|m| &m.primitives) {
        let a = p.custom.iter().find(|c| c.name == SNOW_ATTRIBUTE).expect("_SNOW on every primitive");
        assert_eq!(a.values.len(), p.positions.len());
        assert!(a.values.iter().all(|v| (0.0..=1.0).contains(&v[0]) && (v[1] - v[0] * s.max_depth_m).abs() < 1e-6));
    }
    let mask = cover_mask(&scene, 512).unwrap();
    assert_eq!(mask.width.max(mask.height), 512);
    // the mask agrees with the vertex weights where it is read back
    let p = &scene.meshes[0].primitives[0];
    let w = &p.custom[0].values;
    let err: f32 =
        p.positions.iter().zip(w).map(|(q, v)| (mask.weight_at(q[0], q[2]) - v[0]).abs()).sum::<f32>() / w.len() as f32;
    // the rest is the pixel-centre offset on a rough test terrain (0.11 at 128 px, 0.027 at 512)
    assert!(err < 0.05, "mean |mask − vertex weight| {err}");
    // the PNG stores the weight itself (weight·255)
    let png = Image::from_png(&mask.to_image().encode_png().unwrap()).unwrap();
    let i = (mask.height / 2 * mask.width + mask.width / 2) as usize;
    let stored = verdant::color::linear_to_srgb(png.pixels[i][0]);
    assert!((stored - mask.weights[i]).abs() < 1.5 / 255.0, "{stored} vs {}", mask.weights[i]);

    let atlas = atlas_at(-15.0, 0.6);
    let e = Emitter::default();
    let ps = particles(&e, &atlas).unwrap();
    let report = analyze(&atlas, &e, &ps, Some(&scene), Some(&mask));
    let bands: Vec<&Band> = report.cover_by_slope.iter().filter(|b| b.vertices > 0).collect();
    assert!(bands.len() >= 3, "{:?}", report.cover_by_slope);
    for pair in bands.windows(2) {
        assert!(pair[1].mean_weight <= pair[0].mean_weight + 1e-9, "{:?}", report.cover_by_slope);
    }
    assert_eq!(report.cover_by_slope[0].covered_fraction, 1.0, "gentle slopes are covered");
    let vertices: usize = scene.meshes.iter().map(|m| m.vertex_count()).sum();
    assert_eq!(report.cover_by_altitude.iter().map(|b| b.vertices).sum::<usize>(), vertices);
    assert_eq!(report.near_particles + report.far_particles, ps.len());
    assert_eq!(report.particles_by_kind.values().sum::<usize>(), ps.len());
    assert!((report.terminal_velocity_m_s - e.terminal_velocity_m_s()).abs() < 1e-9);
    assert!(report.mask_coverage.unwrap() > 0.2);

    // the snow layer lies on the covered part, lifted by the depth, and exports cleanly
    let layer = snow_layer(&scene, 0.5).unwrap();
    assert!(layer.meshes.iter().map(|m| m.triangle_count()).sum::<usize>() > 0);
    let dir = tempfile::tempdir().unwrap();
    for (name, sc) in [("terrain_snow.glb", &scene), ("snow_layer.glb", &layer)] {
        let path = dir.path().join(name);
        write_scene(sc, &path).unwrap();
        let v = validate_file(&path, &ValidateOptions::default()).unwrap();
        assert_eq!((v.errors(), v.warnings()), (0, 0), "{v}");
    }
    let back = read_scene(&dir.path().join("terrain_snow.glb")).unwrap();
    assert_eq!(back.meshes[0].primitives[0].custom[0].name, SNOW_ATTRIBUTE, "the attribute survives a round trip");
}

/// Every output of the snow step as bytes.
fn all_outputs(dir: &std::path::Path) -> Vec<Vec<u8>> {
    let atlas = atlas_at(-20.0, 0.6);
    let e = Emitter::default();
    let ps = particles(&e, &atlas).unwrap();
    let mut files = write_snowfall(dir, &atlas, &e, &ps, 0.5).unwrap();
    let mut terrain = terrain();
    apply_cover(&mut terrain, &CoverSettings { snow_line_m: 30.0, snow_line_noise_m: 8.0, ..CoverSettings::default() })
        .unwrap();
    let mask = cover_mask(&terrain, 96).unwrap();
    files.extend(write_cover(dir, &mask, Some(&snow_layer(&terrain, 0.5).unwrap())).unwrap());
    let names: Vec<String> = files.iter().map(|f| f.file_name().unwrap().to_string_lossy().into_owned()).collect();
    assert_eq!(
        names,
        ["flakes.png", "emitter.json", "particles.csv", "snowfall.glb", "cover_mask.png", "snow_layer.glb"]
    );
    files.iter().map(|f| std::fs::read(f).unwrap()).collect()
}

#[test]
fn snowfall_glb_validates_and_outputs_are_identical_at_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let one = with_threads(1, || all_outputs(dir.path()));
    let v = validate_file(&dir.path().join("snowfall.glb"), &ValidateOptions::default()).unwrap();
    assert_eq!((v.errors(), v.warnings()), (0, 0), "{v}");
    let v = validate_file(&dir.path().join("snow_layer.glb"), &ValidateOptions::default()).unwrap();
    assert_eq!((v.errors(), v.warnings()), (0, 0), "{v}");
    let back = read_scene(&dir.path().join("snowfall.glb")).unwrap();
    let instanced: usize = back.nodes.iter().filter_map(|n| n.instances.as_ref()).map(|i| i.len()).sum();
    let e = Emitter::default();
    assert_eq!(instanced, (e.near_count + e.far.unwrap().count) as usize, "one instance per flake");
    assert!(back.meshes.iter().all(|m| m.triangle_count() == 2), "each instanced mesh is one quad");
    let two = with_threads(2, || all_outputs(dir.path()));
    assert_eq!(one.len(), two.len());
    for (k, (a, b)) in one.iter().zip(&two).enumerate() {
        assert!(a == b, "output {k} differs between 1 and 2 threads");
    }
}

#[test]
fn emitter_json_has_the_derived_figures_and_every_field_is_documented() {
    let atlas = atlas_at(-15.0, 0.6);
    let e = Emitter::default();
    let text = emitter_json(&e, &atlas, "flakes.png").unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!((v["terminal_velocity_m_s"].as_f64().unwrap() - e.terminal_velocity_m_s() as f64).abs() < 1e-6);
    assert_eq!(v["atlas"]["cells"].as_array().unwrap().len(), 16);
    // the emitter part reads back as written
    let mut plain = v.as_object().unwrap().clone();
    for derived in ["terminal_velocity_m_s", "time_constant_s", "wind_unit", "atlas"] {
        plain.remove(derived);
    }
    let back = Emitter::from_json(&serde_json::Value::Object(plain).to_string(), "emitter.json").unwrap();
    assert_eq!(back, e);
    let docs = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/snow.md")).unwrap();
    fn keys(v: &serde_json::Value, out: &mut Vec<String>) {
        match v {
            serde_json::Value::Object(m) => m.iter().for_each(|(k, x)| {
                out.push(k.clone());
                keys(x, out)
            }),
            serde_json::Value::Array(a) => a.iter().for_each(|x| keys(x, out)),
            _ => {}
        }
    }
    let mut all = Vec::new();
    keys(&v, &mut all);
    for k in all {
        assert!(docs.contains(&format!("`{k}`")), "docs/snow.md does not document `{k}`");
    }
}

#[test]
fn bad_settings_give_clear_errors() {
    let key = |e: SnowError| match e {
        SnowError::Setting { key, .. } => key,
        other => panic!("expected a setting error, got {other}"),
    };
    let f = FlakeSettings { temperature_c: 5.0, ..FlakeSettings::default() };
    let err = build_atlas(&f).unwrap_err();
    assert!(err.to_string().contains("−40 and +2 °C"), "{err}");
    assert_eq!(key(err), "temperature_c");
    assert_eq!(
        key(build_atlas(&FlakeSettings { humidity: f32::NAN, ..FlakeSettings::default() }).unwrap_err()),
        "humidity"
    );
    assert_eq!(key(build_atlas(&FlakeSettings { cell_px: 4, ..FlakeSettings::default() }).unwrap_err()), "cell_px");

    let json = r#"{"near_radius_m": 20.0, "far": {"outer_radius_m": 10.0, "count": 5, "view_angle_deg": 90}}"#;
    assert_eq!(key(Emitter::from_json(json, "emitter.json").unwrap_err()), "far.outer_radius_m");
    assert_eq!(key(Emitter::from_json(r#"{"drag_kg_s": 0}"#, "e.json").unwrap_err()), "drag_kg_s");
    let err =
        Emitter::from_json("{\n  \"near_count\": 10,\n  \"fall_heigth_m\": 3\n}", "snow/emitter.json").unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, SnowError::Json { line: 3, .. }), "{msg}");
    assert!(
        msg.contains("snow/emitter.json") && msg.contains("fall_heigth_m") && msg.contains("fall_height_m"),
        "{msg}"
    );

    let c = CoverSettings { full_slope_deg: 50.0, max_slope_deg: 40.0, ..CoverSettings::default() };
    let mut scene = terrain();
    assert_eq!(key(apply_cover(&mut scene, &c).unwrap_err()), "full_slope_deg/max_slope_deg");
    // a mask before the cover names the missing step
    let err = cover_mask(&scene, 64).unwrap_err();
    assert!(err.to_string().contains("apply_cover"), "{err}");
}

#[test]
fn the_stored_mask_reads_back_on_its_8_bit_steps_and_in_place() {
    let mut scene = terrain();
    let s = CoverSettings { snow_line_m: 30.0, snow_line_noise_m: 5.0, wind_scour: 0.3, ..CoverSettings::default() };
    apply_cover(&mut scene, &s).unwrap();
    let mask = cover_mask(&scene, 96).unwrap();
    let png = mask.to_image().encode_png().unwrap();
    let back = CoverMask::from_png(&png, mask.min_x, mask.min_z, mask.metres_per_pixel).unwrap();
    assert_eq!((back.width, back.height), (mask.width, mask.height));
    // every weight is the nearest 1/255 step of the computed one (what a cached build reads)
    for (a, b) in mask.weights.iter().zip(&back.weights) {
        assert!((a - b).abs() <= 0.5 / 255.0 + 1e-6, "{a} stored as {b}");
        assert_eq!((b * 255.0).round() / 255.0, *b);
    }
    assert!(back.weights.iter().any(|&w| w > 0.9) && back.weights.iter().any(|&w| w < 0.1), "partly covered");
    // the same place: read at a pixel centre, both give that pixel's value
    let (i, j) = (back.width / 3, back.height / 2);
    let (x, z) =
        (mask.min_x + (i as f32 + 0.5) * mask.metres_per_pixel, mask.min_z + (j as f32 + 0.5) * mask.metres_per_pixel);
    assert!((back.weight_at(x, z) - back.weights[(j * back.width + i) as usize]).abs() < 1e-5);
    assert!((back.weight_at(x, z) - mask.weight_at(x, z)).abs() <= 0.5 / 255.0 + 1e-5);
    // not a PNG: an error naming the remedy, no panic
    let e = CoverMask::from_png(b"not a png", 0.0, 0.0, 1.0).unwrap_err();
    assert!(e.to_string().contains("rebuild with --force"), "{e}");
}
