//! The preview and the terrain LoD chain through the public API, on the embedded demo map.
//!
//! Timing of the preview for a ~1M-triangle terrain (release):
//! `cargo test --release --test preview_lod -- --ignored --nocapture`

use std::time::Instant;

use verdant::lod::{lod_screen_coverage, msft_screen_coverage, terrain_lod_chain, LodError, LodView};
use verdant::scene::preview::{preview_view, terrain_preview, write_png};
use verdant::terrain::budget::DEFAULT_MAX_VERTICES;
use verdant::terrain::build::{build_scene, BuildOptions};
use verdant::terrain::error::measure;
use verdant::terrain::grid::grid;
use verdant::terrain::tin::{tin, TinOptions};

#[test]
fn lod_chain_is_monotone_bounded_and_switches_by_measured_error() {
    let hf = verdant::synth::demo();
    let view = LodView::default();
    let requested = [0.5, 2.0, 8.0, 32.0];
    let levels = terrain_lod_chain(&hf, &requested, None, DEFAULT_MAX_VERTICES, &view).unwrap();
    assert_eq!(levels.len(), 4);
    for (k, l) in levels.iter().enumerate() {
        assert_eq!(l.level, k);
        assert_eq!(l.max_error_requested_m, requested[k]);
        assert!(!l.hit_triangle_limit);
        assert!(l.stats.max_error_m <= requested[k], "level {k}: {} > {}", l.stats.max_error_m, requested[k]);
        assert_eq!(l.stats.samples_covered, hf.width * hf.height);
        // the analyzer's figure, not the mesher's
        assert_eq!(l.stats, measure(&hf, &l.mesh));
        // the same TIN the terrain job would build for that bound
        assert_eq!(
            l.mesh,
            tin(&hf, &TinOptions { max_error_m: requested[k], max_triangles: None, ..TinOptions::default() })
                .unwrap()
                .mesh
        );
        assert!(l.seconds >= 0.0);
    }
    assert_eq!(levels[0].switch_distance_m, 0.0);
    for pair in levels.windows(2) {
        let (fine, coarse) = (&pair[0], &pair[1]);
        assert!(coarse.mesh.triangles.len() <= fine.mesh.triangles.len());
        assert!(coarse.stats.max_error_m >= fine.stats.max_error_m);
        assert!(coarse.switch_distance_m > fine.switch_distance_m, "distances increase");
        // d = ε · H / (2 tan(fov/2) · τ) from the measured ε
        let e = coarse.stats.max_error_m;
        let d = e * 1080.0 / (2.0 * 30f64.to_radians().tan() * view.max_screen_error_px);
        assert!((coarse.switch_distance_m - d).abs() <= 1e-9 * d);
        // at that distance the error is exactly the tolerance on screen
        assert!((view.projected_error_px(e, coarse.switch_distance_m) - view.max_screen_error_px).abs() < 1e-9);
    }
    assert!(levels[3].mesh.triangles.len() < levels[0].mesh.triangles.len() / 4, "coarse levels are much smaller");

    // MSFT_lod coverage: one per level, decreasing, last 0.
    let radius = 0.5 * ((hf.width - 1) as f64 * hf.cell_size_m) * std::f64::consts::SQRT_2;
    let cov = msft_screen_coverage(&levels, radius, &view);
    assert_eq!(cov.len(), 4);
    assert_eq!(cov[3], 0.0);
    assert!(cov.windows(2).all(|w| w[0] > w[1]), "{cov:?}");
    assert_eq!(cov[0] as f64, lod_screen_coverage(radius, levels[1].switch_distance_m, &view) as f32 as f64);

    // deterministic
    let again = terrain_lod_chain(&hf, &requested, None, DEFAULT_MAX_VERTICES, &view).unwrap();
    for (a, b) in levels.iter().zip(&again) {
        assert_eq!((&a.mesh, a.stats, a.switch_distance_m), (&b.mesh, b.stats, b.switch_distance_m));
    }
}

#[test]
fn lod_chain_refuses_non_increasing_errors_and_honours_the_triangle_limit() {
    let hf = verdant::synth::fractal(65, 65, 1.0, 50.0, 0.5, 3);
    let view = LodView::default();
    let err = terrain_lod_chain(&hf, &[1.0, 4.0, 4.0], None, DEFAULT_MAX_VERTICES, &view).unwrap_err();
    assert!(matches!(err, LodError::NotIncreasing { index: 2, .. }), "{err}");
    assert!(err.to_string().contains("strictly increasing"));

    let levels = terrain_lod_chain(&hf, &[0.0, 0.5, 2.0], Some(200), DEFAULT_MAX_VERTICES, &view).unwrap();
    assert!(levels.iter().all(|l| l.mesh.triangles.len() <= 200));
    assert!(levels[0].hit_triangle_limit);
    for pair in levels.windows(2) {
        assert!(pair[1].mesh.triangles.len() <= pair[0].mesh.triangles.len());
        assert!(pair[1].switch_distance_m >= pair[0].switch_distance_m);
    }
}

#[test]
fn preview_of_the_demo_is_a_relief_and_deterministic() {
    let hf = verdant::synth::demo();
    let mesh = tin(&hf, &TinOptions::default()).unwrap().mesh;
    let opts = BuildOptions { chunk_samples: Some(64), skirt_depth_m: Some(4.0), ..BuildOptions::default() };
    let scene = build_scene(&hf, &mesh, &opts).unwrap();
    let a = terrain_preview(&scene, 256);
    assert_eq!((a.width, a.height), (256, 256));
    let v = preview_view(&scene, 256).unwrap();
    assert_eq!((v.width, v.height), (a.width, a.height));
    // every pixel covered, and a spread of shades (a relief, not a flat fill)
    assert!(a.color.iter().all(|c| c[3] == 1.0));
    let lum: Vec<f32> = a.color.iter().map(|c| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]).collect();
    let (lo, hi) = lum.iter().fold((f32::MAX, f32::MIN), |(l, h), &x| (l.min(x), h.max(x)));
    assert!(hi - lo > 0.2, "{lo}..{hi}");
    let b = terrain_preview(&scene, 256);
    assert_eq!(a, b);

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sub/preview.png");
    write_png(&a, &path).unwrap();
    let first = std::fs::read(&path).unwrap();
    write_png(&b, &path).unwrap();
    assert_eq!(first, std::fs::read(&path).unwrap(), "byte-identical PNG");
    let img = image::open(&path).unwrap().to_rgba8();
    assert_eq!(img.dimensions(), (256, 256));
}

#[test]
#[ignore = "timing; run in release with --ignored --nocapture"]
fn preview_of_a_million_triangles_timing() {
    // 709² samples → 2·708² = 1,002,528 triangles.
    let hf = verdant::synth::fractal(709, 709, 1.0, 120.0, 0.5, 11);
    let mesh = grid(&hf, 1).unwrap();
    let scene = build_scene(&hf, &mesh, &BuildOptions::default()).unwrap();
    let tris: usize = scene.meshes.iter().map(|m| m.triangle_count()).sum();
    let _warm = terrain_preview(&scene, 64);
    let start = Instant::now();
    let c = terrain_preview(&scene, 1024);
    let secs = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let png = c.encode_png().unwrap();
    let png_secs = start.elapsed().as_secs_f64();
    println!(
        "preview of {tris} triangles into {}×{}: {secs:.3} s (+ PNG encode {png_secs:.3} s, {} KiB), {} threads",
        c.width,
        c.height,
        png.len() / 1024,
        rayon::current_num_threads()
    );
}

#[test]
#[ignore = "writes $VERDANT_PREVIEW_OUT/preview_demo.png to look at"]
fn write_demo_preview() {
    let Ok(dir) = std::env::var("VERDANT_PREVIEW_OUT") else { return };
    let hf = verdant::synth::demo();
    let mesh = tin(&hf, &TinOptions::default()).unwrap().mesh;
    let opts = BuildOptions { chunk_samples: Some(64), ..BuildOptions::default() };
    let scene = build_scene(&hf, &mesh, &opts).unwrap();
    write_png(&terrain_preview(&scene, 512), &std::path::Path::new(&dir).join("preview_demo.png")).unwrap();
}
