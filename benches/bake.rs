//! Baker benchmark: rasteriser fill rate (million pixels written per second) with the orthographic
//! and the perspective camera, serial and parallel; then a grass-atlas bake-like workload (a
//! synthetic clump of 150 five-segment blades rendered as 4 vertical slices of 256² side by side
//! plus a 256² top view, at 1× and 4× supersampling, dilated, with coverage-preserving mip chains
//! and PNG encoding) and the LoD image analyzer on that clump against a crossed-billboard stand-in.
//!
//! Each figure is the best wall time over the runs, with the CPU time (all threads) of that run:
//! the machine is shared, so CPU ≈ 2 × wall means both cores were ours, CPU ≈ wall about one.
//! Plain `main`, no harness: `cargo bench --bench bake`. `VERDANT_BENCH_RUNS` sets the runs
//! (default 3).

use std::time::Instant;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::cpu_seconds;

use verdant::bake::atlas::{dilate, mip_chain, resolve_supersampled};
use verdant::bake::image::Image;
use verdant::bake::raster::{Camera, DrawOptions, Fragment, OrthoView, PerspectiveView};
use verdant::bake::render::{render_mesh, RenderOptions};
use verdant::bake::views::{lod_image_error, Renderable, ScreenView};
use verdant::mesh::{AlphaMode, Material, Mesh, Primitive};
use verdant::random::mix64;

const IDENTITY: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];

fn runs() -> usize {
    std::env::var("VERDANT_BENCH_RUNS").ok().and_then(|v| v.parse().ok()).unwrap_or(3)
}

/// Best (wall, cpu) seconds of `f` over the runs, and its last result.
fn best<T>(mut f: impl FnMut() -> T) -> (f64, f64, T) {
    let mut out = None;
    let (mut wall, mut cpu) = (f64::INFINITY, f64::NAN);
    for _ in 0..runs() {
        let (t, c) = (Instant::now(), cpu_seconds());
        let r = f();
        let w = t.elapsed().as_secs_f64();
        if w < wall {
            wall = w;
            cpu = cpu_seconds() - c;
        }
        out = Some(r);
    }
    (wall, cpu, out.expect("at least one run"))
}

/// `layers` screen-filling quads facing the camera along −Z, farthest first (every fragment
/// passes the depth test and is written), each with its own vertex colour.
fn layers(layers: usize, half: f32) -> Primitive {
    let mut p = Primitive::default();
    for k in 0..layers {
        let z = -(layers as f32) + k as f32;
        let base = p.positions.len() as u32;
        let s = half * (1.0 - z / 10.0); // grows with distance so the perspective view stays filled
        p.positions.extend_from_slice(&[[-s, -s, z], [s, -s, z], [s, s, z], [-s, s, z]]);
        p.colors.extend_from_slice(&[[k as f32 / layers as f32, 0.5, 0.2, 1.0]; 4]);
        p.indices.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    p
}

fn fill_rate() {
    const SIDE: u32 = 2048;
    const LAYERS: usize = 16;
    let ortho = Camera::Ortho(OrthoView {
        origin: [-1.0, 1.0, 10.0],
        right: [1.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        forward: [0.0, 0.0, -1.0],
        pixels_per_metre: SIDE as f64 / 2.0,
        width: SIDE,
        height: SIDE,
    });
    let persp = Camera::Perspective(PerspectiveView {
        eye: [0.0, 0.0, 10.0],
        target: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_x_deg: 10.0,
        width: SIDE,
        height: SIDE,
        near: 0.1,
    });
    let prim = layers(LAYERS, 1.0);
    let shader = |f: &Fragment| Some(f.color);
    println!("fill rate: {LAYERS} screen-filling quads on {SIDE}², farthest first (all fragments written), shader = vertex colour");
    println!("{:<12} {:<9} {:>12} {:>8} {:>6} {:>10}", "camera", "mode", "fragments", "seconds", "cpu", "Mpixel/s");
    for (name, cam) in [("orthographic", ortho), ("perspective", persp)] {
        for parallel in [false, true] {
            let (wall, cpu, frags) = best(|| {
                let mut c = cam.canvas([0.0; 4]).expect("canvas");
                let s = if parallel {
                    c.draw_camera_par(&cam, &IDENTITY, &prim, &DrawOptions::default(), shader)
                } else {
                    c.draw_camera(&cam, &IDENTITY, &prim, &DrawOptions::default(), shader)
                };
                s.fragments
            });
            let mode = if parallel { "parallel" } else { "serial" };
            println!("{name:<12} {mode:<9} {frags:>12} {wall:>8.3} {cpu:>6.2} {:>10.1}", frags as f64 / wall / 1e6);
        }
    }
}

/// A 1 m grass clump: `blades` strips of five quads, random root, height, lean and facing; one
/// double-sided, alpha-masked material with vertex colours off (root-to-tip green in a texture).
fn grass_clump(blades: u64) -> (Mesh, Vec<Material>, Vec<Image>) {
    let mut p = Primitive { material: Some(0), ..Primitive::default() };
    for b in 0..blades {
        let h = mix64(b ^ 0x6261_6b65);
        let u = |shift: u32| ((h >> shift) & 0xffff) as f32 / 65535.0;
        let (x, z) = (u(0) - 0.5, u(16) - 0.5);
        let height = 0.3 + 0.5 * u(32);
        let yaw = u(48) * std::f32::consts::TAU;
        let (s, c) = yaw.sin_cos();
        let lean = 0.25 * height * (u(8) - 0.5);
        let base = p.positions.len() as u32;
        for k in 0..=5 {
            let t = k as f32 / 5.0;
            let half = 0.012 * (1.0 - t);
            let bend = lean * t * t;
            for side in [-1.0f32, 1.0] {
                p.positions.push([x + side * half * c + bend * s, t * height, z - side * half * s + bend * c]);
                p.uvs.push([(side + 1.0) * 0.5, 1.0 - t]);
            }
        }
        for k in 0..5 {
            let a = base + 2 * k;
            p.indices.extend_from_slice(&[a, a + 1, a + 3, a, a + 3, a + 2]);
        }
    }
    let mut tex = Image::new(8, 64, [0.0; 4]).expect("texture");
    for y in 0..64 {
        for x in 0..8 {
            let t = 1.0 - (y as f32 + 0.5) / 64.0;
            tex.pixels[y * 8 + x] = [0.08, 0.25 + 0.45 * t, 0.04, 1.0];
        }
    }
    let mat = Material {
        base_color_texture: Some(0),
        alpha_mode: AlphaMode::Mask { cutoff: 0.75 },
        double_sided: true,
        ..Material::default()
    };
    (Mesh { name: "clump".into(), primitives: vec![p], extras: None }, vec![mat], vec![tex])
}

/// An orthographic view of the unit clump cell from azimuth `angle` (side) or from above.
fn slice_view(angle: Option<f64>, side_px: u32) -> Camera {
    let ppm = side_px as f64 / 1.2;
    match angle {
        Some(a) => {
            let (s, c) = a.sin_cos();
            let (right, forward) = ([c, 0.0, -s], [-s, 0.0, -c]);
            Camera::Ortho(OrthoView {
                origin: [-0.6 * right[0] - 2.0 * forward[0], 1.1, -0.6 * right[2] - 2.0 * forward[2]],
                right,
                up: [0.0, 1.0, 0.0],
                forward,
                pixels_per_metre: ppm,
                width: side_px,
                height: side_px,
            })
        }
        None => Camera::Ortho(OrthoView::top_down(-0.6, 0.6, -0.6, 0.6, 2.0, side_px)),
    }
}

/// The bake: 4 side slices into a 4·256 × 256 atlas and one 256² top view, each rendered at
/// `ss`× and resolved, dilated, mip-chained and encoded. Returns the PNG bytes written.
fn bake(clump: &(Mesh, Vec<Material>, Vec<Image>), ss: u32) -> usize {
    const VIEW: u32 = 256;
    let render = |cam: Camera| {
        let mut c = cam.canvas([0.0; 4]).expect("canvas");
        render_mesh(&mut c, &cam, &IDENTITY, &clump.0, &clump.1, &clump.2, &RenderOptions::default());
        resolve_supersampled(&Image::from_canvas_owned(c), ss)
    };
    let mut atlas = Image::new(4 * VIEW, VIEW, [0.0; 4]).expect("atlas");
    for k in 0..4 {
        let slice = render(slice_view(Some(k as f64 * std::f64::consts::FRAC_PI_4), VIEW * ss));
        atlas.blit(&slice, k * VIEW, 0);
    }
    let mut top = render(slice_view(None, VIEW * ss));
    let mut bytes = 0;
    for img in [&mut atlas, &mut top] {
        dilate(img, 0.5 / 255.0);
        for level in mip_chain(img, 0.75) {
            bytes += level.image.encode_png().expect("png").len();
        }
    }
    bytes
}

/// Two crossed 1 m × 0.8 m billboards: a stand-in for a clump's billboard LoD.
fn crossed_billboards() -> Mesh {
    let quad = |a: [f32; 3], b: [f32; 3]| Primitive {
        positions: vec![a, b, [b[0], 0.8, b[2]], [a[0], 0.8, a[2]]],
        uvs: vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]],
        indices: vec![0, 1, 2, 0, 2, 3],
        material: Some(0),
        ..Primitive::default()
    };
    Mesh {
        name: "billboards".into(),
        primitives: vec![quad([-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]), quad([0.0, 0.0, 0.5], [0.0, 0.0, -0.5])],
        extras: None,
    }
}

fn main() {
    println!("rayon threads: {}, best of {} runs", rayon::current_num_threads(), runs());
    fill_rate();

    let clump = grass_clump(150);
    println!(
        "\natlas bake: clump of 150 blades ({} triangles), 4 × 256² slices + 256² top view, dilate, mips, PNG",
        clump.0.triangle_count()
    );
    println!("{:<14} {:>8} {:>6} {:>10}", "supersampling", "seconds", "cpu", "PNG bytes");
    for ss in [1, 4] {
        let (wall, cpu, bytes) = best(|| bake(&clump, ss));
        println!("{:<14} {wall:>8.3} {cpu:>6.2} {bytes:>10}", format!("{ss}×"));
    }

    let boards = crossed_billboards();
    let mats = [Material { alpha_mode: AlphaMode::Mask { cutoff: 0.75 }, double_sided: true, ..Material::default() }];
    let distances = [4.0, 8.0, 16.0, 32.0, 64.0, 128.0];
    let (wall, cpu, report) = best(|| {
        lod_image_error(
            &Renderable { mesh: &clump.0, materials: &clump.1, textures: &clump.2 },
            &Renderable { mesh: &boards, materials: &mats, textures: &[] },
            &ScreenView::default(),
            &distances,
        )
    });
    println!(
        "\nLoD image error, clump vs untextured crossed billboards, {} views × {} distances: {wall:.3} s (cpu {cpu:.2})",
        report.views,
        distances.len()
    );
    for d in &report.distances {
        println!(
            "  {:>5} m  canvas {:>3}²  worst IoU {:.3}  worst edge {:>7.2} px  mean edge {:>7.2} px",
            d.distance_m, d.canvas_px[0], d.worst_iou, d.worst_edge_error_px, d.mean_edge_error_px
        );
    }
    println!("  switch distance {:.1} m (never passes: {})", report.switch_distance_m, report.never_passes);
}
