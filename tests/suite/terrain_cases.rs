//! The hard cases of the terrain issue, each end to end through the library: a heightmap file is
//! decoded, meshed, measured, written, re-imported and compared with what was in memory.

use std::path::{Path, PathBuf};

use image::{ImageBuffer, Luma};
use verdant::failure::Failure;
use verdant::heightfield::{DecodeOptions, Encoding};
use verdant::mesh::Scene;
use verdant::terrain::build::BuildOptions;
use verdant::terrain::job::{self, JobError, MeshMode, Source, TerrainJob, TerrainReport};
use verdant::validate::{read_scene, validate_file, ValidateOptions};

fn write_png(dir: &Path, name: &str, w: u32, h: u32, f: impl Fn(u32, u32) -> u16) -> PathBuf {
    let path = dir.join(name);
    ImageBuffer::from_fn(w, h, |i, j| Luma([f(i, j)])).save(&path).unwrap();
    path
}

fn job_for(path: &Path, max_error_m: f64) -> TerrainJob {
    TerrainJob {
        source: Source::File(path.to_owned()),
        decode: DecodeOptions { encoding: Encoding::Auto, height_scale_m: 65535.0, ..DecodeOptions::default() },
        mode: MeshMode::Tin,
        grid_step: 1,
        max_error_m,
        max_triangles: None,
        max_vertices: verdant::terrain::budget::DEFAULT_MAX_VERTICES,
        build: BuildOptions { name: "t".into(), ..BuildOptions::default() },
        quantize: false,
        meshopt: false,
    }
}

/// Runs the job to a .glb, checks the error bound, validates and re-imports the file.
fn run_checked(job: &TerrainJob, dir: &Path, ext: &str) -> (TerrainReport, Scene) {
    let out = dir.join(format!("out.{ext}"));
    let (report, scene) = job::run(job, Some(&out)).unwrap();
    if !report.figures.hit_triangle_limit {
        assert!(
            report.figures.max_error <= job.max_error_m,
            "bound broken: {} > {}",
            report.figures.max_error,
            job.max_error_m
        );
    }
    let up = job.build.base_depth_m.is_none() && job.build.skirt_depth_m.is_none();
    let v = validate_file(&out, &ValidateOptions { up_facing: up }).unwrap();
    assert!(v.ok(), "{v}");
    let back = read_scene(&out).unwrap();
    assert_eq!(back.meshes.len(), scene.meshes.len());
    for (a, b) in scene.meshes.iter().zip(&back.meshes) {
        assert_eq!(a.name, b.name);
        assert_eq!(a.primitives.len(), b.primitives.len());
        for (pa, pb) in a.primitives.iter().zip(&b.primitives) {
            assert_eq!(pa.positions, pb.positions, "positions re-imported equal");
            assert_eq!(pa.normals, pb.normals);
            assert_eq!(pa.uvs, pb.uvs);
            assert_eq!(pa.indices, pb.indices);
        }
    }
    (report, scene)
}

#[test]
fn constant_map_gives_two_triangles() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_png(dir.path(), "c.png", 65, 40, |_, _| 1234);
    let (r, _) = run_checked(&job_for(&path, 0.0), dir.path(), "glb");
    assert_eq!((r.figures.triangles, r.figures.max_error), (2, 0.0));
}

#[test]
fn planar_map_gives_two_triangles() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_png(dir.path(), "p.png", 50, 33, |i, j| (100 + 7 * i + 3 * j) as u16);
    let (r, _) = run_checked(&job_for(&path, 0.0), dir.path(), "glb");
    assert_eq!(r.figures.triangles, 2);
    assert!(r.figures.max_error < 1e-3, "{}", r.figures.max_error);
}

#[test]
fn single_spikes_in_the_middle_and_on_the_border() {
    let dir = tempfile::tempdir().unwrap();
    for (name, si, sj) in [("mid.png", 20, 15), ("border.png", 0, 9), ("edge.png", 17, 29)] {
        let path = write_png(dir.path(), name, 41, 30, |i, j| if (i, j) == (si, sj) { 5000 } else { 10 });
        let (r, scene) = run_checked(&job_for(&path, 0.5), dir.path(), "glb");
        assert_eq!(r.figures.max_error, 0.0, "{name}: a spike is met exactly");
        let spike = [si as f32, 5000.0, sj as f32];
        assert!(scene.meshes[0].primitives[0].positions.contains(&spike), "{name}: spike vertex present");
    }
}

#[test]
fn vertical_cliff() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_png(dir.path(), "cliff.png", 64, 64, |i, _| if i < 31 { 0 } else { 60000 });
    let (r, _) = run_checked(&job_for(&path, 1.0), dir.path(), "glb");
    assert!(r.figures.triangles < 2 * 63 * 63 / 10, "a straight cliff needs few triangles: {}", r.figures.triangles);
}

#[test]
fn white_noise_keeps_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let path =
        write_png(dir.path(), "noise.png", 48, 48, |i, j| (verdant::random::mix64((i * 48 + j) as u64) >> 48) as u16);
    let (r, _) = run_checked(&job_for(&path, 100.0), dir.path(), "glb");
    assert!(
        r.figures.triangles as f64 > 0.8 * r.figures.full_grid_triangles as f64,
        "noise approaches the full grid: {}",
        r.figures.triangles
    );
}

#[test]
fn checkerboard() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_png(dir.path(), "check.png", 24, 24, |i, j| if (i + j) % 2 == 0 { 0 } else { 1000 });
    let (r, _) = run_checked(&job_for(&path, 0.1), dir.path(), "glb");
    assert!(r.figures.max_error <= 0.1);
}

#[test]
fn non_square_301_by_17_as_gltf_and_obj() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_png(dir.path(), "wide.png", 301, 17, |i, j| ((i * 37 + j * 1009) % 4000) as u16);
    let (r, _) = run_checked(&job_for(&path, 2.0), dir.path(), "gltf");
    assert_eq!((r.figures.width, r.figures.height), (301, 17));
    let out = dir.path().join("wide.obj");
    job::run(&job_for(&path, 2.0), Some(&out)).unwrap();
    assert!(validate_file(&out, &ValidateOptions { up_facing: true }).unwrap().ok());
}

#[test]
fn two_by_two_and_zero_area_maps() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_png(dir.path(), "tiny.png", 2, 2, |i, j| (i * 10 + j * 20) as u16);
    let (r, _) = run_checked(&job_for(&path, 0.0), dir.path(), "glb");
    assert_eq!(r.figures.triangles, 2);
    for (w, h) in [(1, 9), (9, 1), (1, 1)] {
        let path = write_png(dir.path(), &format!("z{w}x{h}.png"), w, h, |_, _| 5);
        let out = dir.path().join(format!("z{w}x{h}.glb"));
        let e = job::run(&job_for(&path, 1.0), Some(&out)).unwrap_err();
        assert!(matches!(e, JobError::Terrain { .. }), "{e}");
        assert_eq!(e.exit_code(), 2);
        assert!(e.to_string().contains(&format!("z{w}x{h}.png")), "{e}");
        assert!(!out.exists());
    }
}

#[test]
fn sixteen_bit_full_range() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_png(dir.path(), "full.png", 33, 33, |i, j| {
        if (i, j) == (16, 16) {
            65535
        } else if i == 0 {
            0
        } else {
            ((i * 2000) % 65536) as u16
        }
    });
    let (r, scene) = run_checked(&job_for(&path, 0.5), dir.path(), "glb");
    let ys: Vec<f32> = scene.meshes[0].primitives[0].positions.iter().map(|p| p[1]).collect();
    assert!(ys.contains(&65535.0) && ys.contains(&0.0));
    assert!(r.figures.max_error <= 0.5);
}

#[test]
fn hgt_with_voids() {
    let dir = tempfile::tempdir().unwrap();
    let side = 121usize;
    let mut bytes = Vec::new();
    for j in 0..side {
        for i in 0..side {
            let v: i16 = if (40..45).contains(&i) && (60..62).contains(&j) { -32768 } else { (i * 3 + j * 2) as i16 };
            bytes.extend_from_slice(&v.to_be_bytes());
        }
    }
    let path = dir.path().join("N10E010.hgt");
    std::fs::write(&path, bytes).unwrap();
    let mut job = job_for(&path, 0.5);
    job.decode.cell_size_m = 90.0;
    let (r, _) = run_checked(&job, dir.path(), "glb");
    assert_eq!(r.figures.voids_filled, 10);
    assert_eq!(r.encoding, Encoding::Hgt);
}

#[test]
fn triangle_limit_reports_the_achieved_error() {
    let dir = tempfile::tempdir().unwrap();
    let path =
        write_png(dir.path(), "f.png", 65, 65, |i, j| (verdant::random::mix64((i * 65 + j) as u64) >> 52) as u16);
    let mut job = job_for(&path, 0.0);
    job.max_triangles = Some(200);
    let (r, _) = run_checked(&job, dir.path(), "glb");
    assert!(r.figures.hit_triangle_limit);
    assert!(r.figures.triangles <= 200, "{}", r.figures.triangles);
    assert!(r.figures.max_error > 0.0);
}

#[test]
fn chunks_skirts_and_base_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_png(dir.path(), "hill.png", 70, 50, |i, j| {
        (((i as f64 / 10.0).sin() * (j as f64 / 7.0).cos() + 1.0) * 2000.0) as u16
    });
    let mut job = job_for(&path, 1.0);
    job.build.chunk_samples = Some(32);
    let (r, scene) = run_checked(&job, dir.path(), "glb");
    assert_eq!(scene.meshes.len(), 3 * 2, "70×50 samples in 32-sample chunks");
    assert_eq!(r.output.as_ref().unwrap().triangles, r.figures.triangles, "chunking keeps every triangle");
    job.build.skirt_depth_m = Some(5.0);
    let (r, _) = run_checked(&job, dir.path(), "gltf");
    assert!(r.output.as_ref().unwrap().triangles > r.figures.triangles);
    job.build.skirt_depth_m = None;
    job.build.chunk_samples = None;
    job.build.base_depth_m = Some(10.0);
    let (r, _) = run_checked(&job, dir.path(), "glb");
    let b = r.output.unwrap().bounds.unwrap();
    assert!(b.min[1] <= -10.0 + 1e-3, "base {} below the lowest sample", b.min[1]);
}

#[test]
fn the_terrain_is_textured_from_its_layers() {
    // a plain on the left, a 60° ramp on the right: grass, then rock, in the base colour that the
    // written file's material samples through the planar UVs
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (65u32, 17u32);
    let png = write_png(dir.path(), "ramp.png", w, h, |x, _| if x < 32 { 0 } else { ((x - 32) * 1732) as u16 });
    let mut job = job_for(&png, 0.01);
    job.decode.height_scale_m = 65.535;
    let (report, _) = run_checked(&job, dir.path(), "glb");
    let back = read_scene(&dir.path().join("out.glb")).unwrap();
    let m = &back.materials[0];
    let t = m.base_color_texture.expect("the terrain material has a base-colour texture");
    assert_eq!(m.base_color, [1.0; 4], "the texture's colour is what shows");
    assert!(back.meshes.iter().flat_map(|x| &x.primitives).all(|p| !p.uvs.is_empty()));
    let img = image::load_from_memory(&back.textures[t].png).unwrap().to_rgb8();
    assert_eq!((img.width(), img.height()), (64, 16));
    let grass = img.get_pixel(4, 8).0;
    let rock = img.get_pixel(60, 8).0;
    assert!(grass[1] > grass[0] && grass[1] > grass[2], "gentle ground is green: {grass:?}");
    assert!(rock[0].abs_diff(rock[1]) < 12 && rock[1].abs_diff(rock[2]) < 12, "a cliff is grey rock: {rock:?}");
    let c = &report.figures.layers.coverage;
    assert_eq!(report.figures.layers.layers, ["grass", "scree", "rock", "snow"]);
    assert!((c.iter().sum::<f64>() - 1.0).abs() < 1e-9 && c[0] > 0.3 && c[2] > 0.3, "{c:?}");
}

/// A Terrain-RGB tile near 9,000 m (decimetre heights no f32 holds exactly), cells of 30.87 m (not
/// exact in f32 either): at a bound of a decimetre, re-read from the written file,
/// the surface through the stored f32 vertices stays within the bound at every sample, measured
/// against the PNG's heights decoded in f64 — and a bound below the f32 step is refused.
#[test]
fn the_bound_holds_in_the_bytes_written_at_high_altitude() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (97u32, 83u32);
    // decimetres above −10 000 m: 8 450 .. 8 950 m of smooth relief
    let dm = |i: u32, j: u32| -> u32 {
        let (x, z) = (i as f64 / 7.0, j as f64 / 5.0);
        let m = 8700.0 + 250.0 * (x.sin() * z.cos());
        ((m + 10000.0) * 10.0).round() as u32
    };
    let path = dir.path().join("high.png");
    image::RgbImage::from_fn(w, h, |i, j| {
        let v = dm(i, j);
        image::Rgb([(v >> 16) as u8, (v >> 8 & 255) as u8, (v & 255) as u8])
    })
    .save(&path)
    .unwrap();
    let cell = 30.87;
    let mut job = job_for(&path, 0.1);
    job.decode = DecodeOptions { encoding: Encoding::TerrainRgb, cell_size_m: cell, ..DecodeOptions::default() };
    let (report, _) = run_checked(&job, dir.path(), "glb");
    assert!(report.figures.max_error <= 0.1, "{} over the bound as written", report.figures.max_error);

    // Independently: the file's triangles, located by their vertices' samples, evaluated through
    // the stored f32 vertices at each sample's place.
    let truth = |i: i64, j: i64| dm(i as u32, j as u32) as f64 * 0.1 - 10000.0;
    let (worst, covered) = error_in_file(&dir.path().join("out.glb"), cell, &truth);
    assert_eq!(covered, (w * h) as usize, "every sample under a triangle of the file");
    assert!(worst <= 0.1, "the written surface is {worst} m off the map");
    assert!(
        (worst - report.figures.max_error).abs() < 1e-9,
        "independent {worst} vs reported {}",
        report.figures.max_error
    );
    // the f32 rounding is really at play here: the exact triangulation alone is not the figure
    assert!(
        report.figures.max_error_f64 != report.figures.max_error,
        "{} {}",
        report.figures.max_error_f64,
        report.figures.max_error
    );

    // 0.0002 m is below half the f32 step at 8 900 m (4.9e-4 m): no triangulation can meet it.
    job.max_error_m = 0.0002;
    let err = job::run(&job, Some(&dir.path().join("fine.glb"))).unwrap_err();
    assert_eq!(err.exit_code(), 2);
    let msg = err.to_string();
    assert!(msg.contains("32-bit floats") && msg.contains("--max-error 0.0002"), "{msg}");
    assert!(!dir.path().join("fine.glb").exists());
}

/// The largest |surface − truth| over the samples under the surface triangles of a terrain file
/// as written, and how many samples are covered, computed independently of the library: every
/// mesh placed by its node (translation + scale · position, as KHR_mesh_quantization stores it;
/// identity for f32 files), vertices mapped back to samples by x/cell and z/cell, the stored
/// triangle evaluated at each sample's place (i·cell, j·cell) in f64. Triangles facing sideways or
/// down (skirts, base) are skipped.
fn error_in_file(path: &Path, cell: f64, truth: &dyn Fn(i64, i64) -> f64) -> (f64, usize) {
    let back = read_scene(path).unwrap();
    let (mut worst, mut covered) = (0.0f64, std::collections::HashSet::new());
    for node in back.nodes.iter().filter(|n| n.mesh.is_some()) {
        assert_eq!(node.rotation, [0.0, 0.0, 0.0, 1.0], "terrain nodes are not rotated");
        let (t, sc) = (node.translation.map(|c| c as f64), node.scale.map(|c| c as f64));
        for prim in &back.meshes[node.mesh.unwrap()].primitives {
            let world: Vec<[f64; 3]> =
                prim.positions.iter().map(|p| [0, 1, 2].map(|a| t[a] + sc[a] * p[a] as f64)).collect();
            for tri in prim.indices.chunks_exact(3) {
                let p = [tri[0], tri[1], tri[2]].map(|k| world[k as usize]);
                let d = (p[1][0] - p[0][0]) * (p[2][2] - p[0][2]) - (p[2][0] - p[0][0]) * (p[1][2] - p[0][2]);
                // counter-clockwise from +Y is a negative d in (x, z); skirts and the base are not surface
                if d >= 0.0 {
                    continue;
                }
                let ij = p.map(|q| [(q[0] / cell).round() as i64, (q[2] / cell).round() as i64]);
                let (i0, i1) = (ij.iter().map(|q| q[0]).min().unwrap(), ij.iter().map(|q| q[0]).max().unwrap());
                let (j0, j1) = (ij.iter().map(|q| q[1]).min().unwrap(), ij.iter().map(|q| q[1]).max().unwrap());
                for j in j0..=j1 {
                    for i in i0..=i1 {
                        let o = |a: [i64; 2], b: [i64; 2]| (b[0] - a[0]) * (j - a[1]) - (b[1] - a[1]) * (i - a[0]);
                        let s = [o(ij[1], ij[2]), o(ij[2], ij[0]), o(ij[0], ij[1])];
                        if !(s.iter().all(|&v| v >= 0) || s.iter().all(|&v| v <= 0)) {
                            continue;
                        }
                        let (x, z) = (i as f64 * cell, j as f64 * cell);
                        let l1 = ((x - p[0][0]) * (p[2][2] - p[0][2]) - (p[2][0] - p[0][0]) * (z - p[0][2])) / d;
                        let l2 = ((p[1][0] - p[0][0]) * (z - p[0][2]) - (x - p[0][0]) * (p[1][2] - p[0][2])) / d;
                        let y = p[0][1] + l1 * (p[1][1] - p[0][1]) + l2 * (p[2][1] - p[0][1]);
                        worst = worst.max((y - truth(i, j)).abs());
                        covered.insert((i, j));
                    }
                }
            }
        }
    }
    (worst, covered.len())
}

/// `--quantize` (KHR_mesh_quantization) and `--compress` (plus EXT_meshopt_compression) on a
/// chunked terrain with skirts: the bound holds for the 16-bit vertices as the file places them,
/// the compressed file reads back equal to the quantized one and is smaller, both validate, and
/// an .obj is refused.
#[test]
fn quantized_and_compressed_terrains_keep_the_bound_as_stored() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (130u32, 90u32);
    let v = |i: u32, j: u32| -> u16 {
        let (x, z) = (i as f64 / 9.0, j as f64 / 6.0);
        (30000.0 + 20000.0 * (x.sin() * z.cos()) + 900.0 * ((i * 5 + j * 3) % 7) as f64) as u16
    };
    let path = write_png(dir.path(), "q.png", w, h, v);
    // gray: offset + v / 65535 · scale, a decimal scale no f32 holds exactly
    let (scale, offset, cell) = (2345.6, 812.3, 7.5);
    let truth = |i: i64, j: i64| offset + v(i as u32, j as u32) as f64 / 65535.0 * scale;
    let mut job = job_for(&path, 0.25);
    job.decode = DecodeOptions {
        encoding: Encoding::Gray,
        height_scale_m: scale,
        height_offset_m: offset,
        cell_size_m: cell,
        ..DecodeOptions::default()
    };
    job.build =
        BuildOptions { chunk_samples: Some(32), skirt_depth_m: Some(4.0), name: "q".into(), ..BuildOptions::default() };
    let mut sizes = Vec::new();
    let mut scenes = Vec::new();
    for (name, quantize, meshopt) in
        [("f32.glb", false, false), ("quantized.glb", true, false), ("compressed.glb", true, true)]
    {
        let (mut job, out) = (job.clone(), dir.path().join(name));
        (job.quantize, job.meshopt) = (quantize, meshopt);
        let (report, _) = job::run(&job, Some(&out)).unwrap();
        assert!(report.figures.max_error <= 0.25, "{name}: {} as written", report.figures.max_error);
        let (worst, covered) = error_in_file(&out, cell, &truth);
        assert_eq!(covered, (w * h) as usize, "{name}");
        assert!(worst <= 0.25, "{name}: the file is {worst} m off the map");
        assert!(
            (worst - report.figures.max_error).abs() < 1e-9,
            "{name}: independent {worst} vs reported {}",
            report.figures.max_error
        );
        let v = validate_file(&out, &ValidateOptions { up_facing: false }).unwrap();
        assert!(v.ok(), "{name}: {v}");
        sizes.push(std::fs::metadata(&out).unwrap().len());
        scenes.push(read_scene(&out).unwrap());
    }
    for (a, b) in scenes[1].meshes.iter().zip(&scenes[2].meshes) {
        for (pa, pb) in a.primitives.iter().zip(&b.primitives) {
            assert_eq!(pa.positions, pb.positions, "{}: positions", a.name);
            assert_eq!(pa.normals, pb.normals, "{}: normals", a.name);
            assert_eq!(pa.uvs, pb.uvs, "{}: uvs", a.name);
            // meshoptimizer's index codec may rotate a triangle's corners (winding kept)
            let rotated = |t: &[u32]| {
                let k = (0..3).min_by_key(|&k| t[k]).unwrap();
                [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
            };
            let (ta, tb): (Vec<_>, Vec<_>) =
                (pa.indices.chunks(3).map(rotated).collect(), pb.indices.chunks(3).map(rotated).collect());
            assert_eq!(ta, tb, "{}: the same triangles in the same order and winding", a.name);
        }
    }
    let mut without_indices = scenes.clone();
    for s in without_indices.iter_mut() {
        s.meshes.iter_mut().flat_map(|m| m.primitives.iter_mut()).for_each(|p| p.indices.clear());
    }
    assert_eq!(without_indices[1], without_indices[2], "the compressed file reads back as the quantized one");
    // the textures (base colour, normal map: PNG either way) are the same bytes in all three
    let textures: u64 = scenes[0].textures.iter().map(|t| t.png.len() as u64).sum();
    let sizes: Vec<u64> = sizes.iter().map(|s| s - textures).collect();
    assert!(
        sizes[1] < sizes[0] && sizes[2] * 2 < sizes[1],
        "bytes besides textures, f32, quantized, compressed: {sizes:?}"
    );
    let json = String::from_utf8_lossy(&std::fs::read(dir.path().join("compressed.glb")).unwrap()).to_string();
    assert!(json.contains("KHR_mesh_quantization") && json.contains("EXT_meshopt_compression"));

    // .gltf + .bin: the compressed data in the .bin, read back equal to the .glb
    let mut gltf = job.clone();
    (gltf.quantize, gltf.meshopt) = (true, true);
    job::run(&gltf, Some(&dir.path().join("compressed.gltf"))).unwrap();
    let back = read_scene(&dir.path().join("compressed.gltf")).unwrap();
    assert_eq!(back.meshes, scenes[2].meshes, "the .gltf reads back as the .glb");
    assert!(validate_file(&dir.path().join("compressed.gltf"), &ValidateOptions { up_facing: false }).unwrap().ok());

    let mut obj = job.clone();
    obj.quantize = true;
    let err = job::run(&obj, Some(&dir.path().join("q.obj"))).unwrap_err();
    assert!(err.to_string().contains("glTF"), "{err}");
}

/// A map wider than 16-bit sample numbers cannot be quantized on its own grid: refused up front.
#[test]
fn quantizing_a_map_over_65536_samples_wide_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_png(dir.path(), "wide.png", 65537, 2, |i, _| (i % 5000) as u16);
    let mut job = job_for(&path, 1.0);
    job.quantize = true;
    let err = job::run(&job, Some(&dir.path().join("wide.glb"))).unwrap_err();
    assert_eq!(err.exit_code(), 2);
    assert!(err.to_string().contains("65536"), "{err}");
    assert!(!dir.path().join("wide.glb").exists());
}

/// A damaged EXT_meshopt_compression file (found by review): a triangle list whose count is not a
/// multiple of 3 made meshoptimizer's C decoder abort the process, and counts or a fallback length
/// of 2^40…2^62 made it allocate without bound. Each is now a parse error naming the view.
#[test]
fn damaged_meshopt_views_are_refused_not_aborted() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_png(dir.path(), "m.png", 40, 30, |i, j| ((i * 97 + j * 31) % 400) as u16 * 50);
    let mut job = job_for(&path, 2.0);
    (job.quantize, job.meshopt) = (true, true);
    job::run(&job, Some(&dir.path().join("m.gltf"))).unwrap();
    let text = std::fs::read_to_string(dir.path().join("m.gltf")).unwrap();
    let good: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(validate_file(&dir.path().join("m.gltf"), &ValidateOptions { up_facing: false }).unwrap().ok());
    let views = good["bufferViews"].as_array().unwrap();
    let ext = |v: &serde_json::Value| v["extensions"]["EXT_meshopt_compression"].clone();
    let tri = views.iter().position(|v| ext(v)["mode"] == "TRIANGLES").unwrap();
    let attr = views.iter().position(|v| ext(v)["mode"] == "ATTRIBUTES").unwrap();
    let fallback = good["buffers"].as_array().unwrap().iter().position(|b| b.get("extensions").is_some()).unwrap();
    let cases: Vec<(&str, Box<dyn Fn(&mut serde_json::Value)>)> = vec![
        (
            "count not a multiple of 3",
            Box::new(move |j| {
                let c = j["bufferViews"][tri]["extensions"]["EXT_meshopt_compression"]["count"].as_u64().unwrap();
                j["bufferViews"][tri]["extensions"]["EXT_meshopt_compression"]["count"] = (c + 1).into();
            }),
        ),
        (
            "a count of 2^40",
            Box::new(move |j| {
                j["bufferViews"][attr]["extensions"]["EXT_meshopt_compression"]["count"] = (1u64 << 40).into()
            }),
        ),
        (
            "a count of 2^60",
            Box::new(move |j| {
                j["bufferViews"][attr]["extensions"]["EXT_meshopt_compression"]["count"] = (1u64 << 60).into()
            }),
        ),
        (
            "a stride of 6",
            Box::new(move |j| j["bufferViews"][attr]["extensions"]["EXT_meshopt_compression"]["byteStride"] = 6.into()),
        ),
        (
            "compressed bytes past the buffer",
            Box::new(move |j| {
                j["bufferViews"][attr]["extensions"]["EXT_meshopt_compression"]["byteOffset"] = (1u64 << 40).into()
            }),
        ),
    ];
    for (what, damage) in cases {
        let mut j = good.clone();
        damage(&mut j);
        let bad = dir.path().join("bad.gltf");
        std::fs::write(&bad, serde_json::to_vec(&j).unwrap()).unwrap();
        let err = validate_file(&bad, &ValidateOptions { up_facing: false })
            .err()
            .unwrap_or_else(|| panic!("{what}: accepted"));
        assert!(err.to_string().contains("EXT_meshopt_compression"), "{what}: {err}");
    }
    // a fallback buffer declaring 2^62 bytes is read only as far as its views reach
    let mut j = good.clone();
    j["buffers"][fallback]["byteLength"] = (1u64 << 62).into();
    std::fs::write(dir.path().join("bad.gltf"), serde_json::to_vec(&j).unwrap()).unwrap();
    let _ = validate_file(&dir.path().join("bad.gltf"), &ValidateOptions { up_facing: false });
}

/// A coarse TIN over rolling hills is lit like the map itself through its normal map, checked in
/// the bytes written: at every texel centre, the file's interpolated vertex normal and TANGENT
/// (w = +1, bitangent N × T up the image) turn the decoded texel into a normal within a degree of
/// the map's own (central differences, bilinear between samples), where the vertex normals alone
/// are several degrees off; the report's figures are these.
#[test]
fn a_coarse_terrain_is_lit_like_the_map_through_its_normal_map() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (97u32, 65u32);
    let height = |i: u32, j: u32| -> u16 {
        let (x, z) = (i as f64 / 6.0, j as f64 / 4.5);
        (1000.0 + 150.0 * x.sin() * z.cos() + 40.0 * (2.3 * x + z).sin()).round() as u16
    };
    let png = write_png(dir.path(), "hills.png", w, h, height);
    let cell = 10.0;
    let mut job = job_for(&png, 25.0);
    job.decode.cell_size_m = cell;
    let (report, _) = run_checked(&job, dir.path(), "glb");
    let nm = &report.figures.normal_map;
    assert_eq!(nm.map_px, [128, 64]);
    let back = read_scene(&dir.path().join("out.glb")).unwrap();
    let m = &back.materials[0];
    let t = m.normal_texture.expect("the terrain material has a normal map");
    let img = image::load_from_memory(&back.textures[t].png).unwrap().to_rgb8();
    assert_eq!([img.width(), img.height()], nm.map_px);

    // the map's normal at sample coordinates (s, t), from the PNG's heights
    let hgt = |i: i64, j: i64| height(i.clamp(0, w as i64 - 1) as u32, j.clamp(0, h as i64 - 1) as u32) as f64;
    let sample_normal = |i: i64, j: i64| -> [f64; 3] {
        let (i0, i1) = ((i - 1).max(0), (i + 1).min(w as i64 - 1));
        let (j0, j1) = ((j - 1).max(0), (j + 1).min(h as i64 - 1));
        let dx = (hgt(i1, j) - hgt(i0, j)) / ((i1 - i0) as f64 * cell);
        let dz = (hgt(i, j1) - hgt(i, j0)) / ((j1 - j0) as f64 * cell);
        let l = (dx * dx + 1.0 + dz * dz).sqrt();
        [-dx / l, 1.0 / l, -dz / l]
    };
    let unit = |v: [f64; 3]| {
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|c| c / l)
    };
    let field = |s: f64, t: f64| -> [f64; 3] {
        let (i0, j0) = (s.floor() as i64, t.floor() as i64);
        let (fs, ft) = (s - i0 as f64, t - j0 as f64);
        let (a, b, c, d) = (
            sample_normal(i0, j0),
            sample_normal(i0 + 1, j0),
            sample_normal(i0, j0 + 1),
            sample_normal(i0 + 1, j0 + 1),
        );
        unit(std::array::from_fn(|k| {
            (a[k] * (1.0 - fs) + b[k] * fs) * (1.0 - ft) + (c[k] * (1.0 - fs) + d[k] * fs) * ft
        }))
    };
    let angle = |a: [f64; 3], b: [f64; 3]| {
        let (a, b) = (unit(a), unit(b));
        (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0).acos().to_degrees()
    };
    let (mut seen, mut sum_with, mut max_with, mut sum_without) = (0usize, 0.0f64, 0.0f64, 0.0f64);
    let mut done = vec![false; (img.width() * img.height()) as usize];
    for p in back.meshes.iter().flat_map(|m| &m.primitives) {
        assert_eq!(p.tangents.len(), p.positions.len(), "TANGENT on every terrain vertex");
        for (n, tg) in p.normals.iter().zip(&p.tangents) {
            let d = n[0] * tg[0] + n[1] * tg[1] + n[2] * tg[2];
            assert!(d.abs() < 1e-5 && tg[3] == 1.0, "tangent {tg:?} against normal {n:?}");
        }
        for tri in p.indices.chunks_exact(3) {
            let v = [tri[0], tri[1], tri[2]].map(|k| k as usize);
            let uv = v.map(|k| p.uvs[k].map(|c| c as f64));
            let area = (uv[1][0] - uv[0][0]) * (uv[2][1] - uv[0][1]) - (uv[2][0] - uv[0][0]) * (uv[1][1] - uv[0][1]);
            for y in 0..img.height() {
                for x in 0..img.width() {
                    let (u, vv) = ((x as f64 + 0.5) / img.width() as f64, (y as f64 + 0.5) / img.height() as f64);
                    let l1 = ((u - uv[0][0]) * (uv[2][1] - uv[0][1]) - (uv[2][0] - uv[0][0]) * (vv - uv[0][1])) / area;
                    let l2 = ((uv[1][0] - uv[0][0]) * (vv - uv[0][1]) - (u - uv[0][0]) * (uv[1][1] - uv[0][1])) / area;
                    let bary = [1.0 - l1 - l2, l1, l2];
                    let k = (y * img.width() + x) as usize;
                    if done[k] || bary.iter().any(|&b| b < -1e-9) {
                        continue;
                    }
                    done[k] = true;
                    let lerp = |f: &dyn Fn(usize) -> [f64; 3]| -> [f64; 3] {
                        std::array::from_fn(|c| (0..3).map(|q| bary[q] * f(v[q])[c]).sum())
                    };
                    let n = unit(lerp(&|i| p.normals[i].map(|c| c as f64)));
                    let t0 = lerp(&|i| [0, 1, 2].map(|c| p.tangents[i][c] as f64));
                    let d = t0[0] * n[0] + t0[1] * n[1] + t0[2] * n[2];
                    let t = unit([0, 1, 2].map(|c| t0[c] - d * n[c]));
                    let b = [n[1] * t[2] - n[2] * t[1], n[2] * t[0] - n[0] * t[2], n[0] * t[1] - n[1] * t[0]];
                    let px = img.get_pixel(x, y).0.map(|c| c as f64 / 255.0 * 2.0 - 1.0);
                    let shaded: [f64; 3] = std::array::from_fn(|c| px[0] * t[c] + px[1] * b[c] + px[2] * n[c]);
                    let truth = field(u * (w - 1) as f64, vv * (h - 1) as f64);
                    let (with, without) = (angle(shaded, truth), angle(n, truth));
                    seen += 1;
                    sum_with += with;
                    max_with = max_with.max(with);
                    sum_without += without;
                }
            }
        }
    }
    assert_eq!(seen, done.len(), "every texel under a triangle of the file");
    let (mean_with, mean_without) = (sum_with / seen as f64, sum_without / seen as f64);
    assert!(max_with < 1.0 && mean_with < 0.3, "lit through the map: mean {mean_with}°, max {max_with}°");
    assert!(mean_without > 3.0, "the coarse mesh alone is off by only {mean_without}°: the case is too easy");
    assert!((mean_with - nm.mean_error_deg).abs() < 0.01 && (max_with - nm.max_error_deg).abs() < 0.01, "{nm:?}");
    assert!((mean_without - nm.mean_error_without_deg).abs() < 0.01, "{nm:?}");
}
