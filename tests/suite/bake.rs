//! The baker through the public API: both cameras against analytic projections, materials and
//! alpha modes, perspective-correct texturing, near-plane clipping, dilation, coverage-preserving
//! mips, image comparison, the LoD image analyzer and determinism across thread counts.

use verdant::bake::atlas::{box_mip_chain, coverage, dilate, mip_chain, resolve_supersampled, write_mip_pngs};
use verdant::bake::compare::compare;
use verdant::bake::image::Image;
use verdant::bake::raster::{Camera, DrawOptions, OrthoView, PerspectiveView};
use verdant::bake::render::{render_mesh, RenderOptions};
use verdant::bake::views::{
    lod_image_error, switch_search, switch_search_chain, Candidate, LodImageOptions, Renderable, ScreenView,
    SwitchSearch,
};
use verdant::mesh::{AlphaMode, Material, Mesh, Primitive};

const IDENTITY: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];

/// An axis-aligned quad in the plane z = `z`, counter-clockwise seen from +Z, uv (0,0) at its
/// top-left corner (glTF: v down).
fn quad_xy(x0: f32, x1: f32, y0: f32, y1: f32, z: f32) -> Primitive {
    Primitive {
        positions: vec![[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]],
        normals: vec![[0.0, 0.0, 1.0]; 4],
        uvs: vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]],
        indices: vec![0, 1, 2, 0, 2, 3],
        material: Some(0),
        ..Primitive::default()
    }
}

fn mesh(primitives: Vec<Primitive>) -> Mesh {
    Mesh { name: "test".into(), primitives, extras: None }
}

/// Looking down −Z from z = 10 at x ∈ [0, w/ppm], y ∈ [0, h/ppm].
fn front_ortho(ppm: f64, width: u32, height: u32) -> OrthoView {
    OrthoView {
        origin: [0.0, height as f64 / ppm, 10.0],
        right: [1.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        forward: [0.0, 0.0, -1.0],
        pixels_per_metre: ppm,
        width,
        height,
    }
}

fn front_perspective(eye_z: f64, fov_x_deg: f64, width: u32, height: u32) -> PerspectiveView {
    PerspectiveView {
        eye: [0.0, 0.0, eye_z],
        target: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_x_deg,
        width,
        height,
        near: 0.01,
    }
}

/// Pixels whose centre lies inside the pixel-space rectangle, and whether any centre is within
/// `margin` of its border (where snapping may decide).
fn expected_rect(width: u32, height: u32, x: [f64; 2], y: [f64; 2]) -> Vec<bool> {
    let mut out = Vec::new();
    for py in 0..height {
        for px in 0..width {
            let (cx, cy) = (px as f64 + 0.5, py as f64 + 0.5);
            out.push(cx > x[0] && cx < x[1] && cy > y[0] && cy < y[1]);
        }
    }
    out
}

fn far_from_edges(width: u32, height: u32, x: [f64; 2], y: [f64; 2]) -> bool {
    let near = |c: f64, e: f64| (c - e).abs() < 1.0 / 64.0;
    !(0..width).any(|p| near(p as f64 + 0.5, x[0]) || near(p as f64 + 0.5, x[1]))
        && !(0..height).any(|p| near(p as f64 + 0.5, y[0]) || near(p as f64 + 0.5, y[1]))
}

#[test]
fn unit_quad_covers_exactly_its_projected_pixels_with_both_cameras() {
    let q = quad_xy(1.3, 3.55, 0.7, 2.2, 0.0);
    let m = mesh(vec![q]);
    let mats = [Material::default()];
    // Orthographic, 4 px per metre on a 20×12 canvas: x → 4x, y → 4·(3 − y).
    let ortho = front_ortho(4.0, 20, 12);
    let (rx, ry) = ([1.3 * 4.0, 3.55 * 4.0], [(3.0 - 2.2) * 4.0, (3.0 - 0.7) * 4.0]);
    // Perspective from z = 8 with a 50° field of view on 64×48: project the corners.
    let persp = front_perspective(8.0, 50.0, 64, 48);
    let a = persp.to_pixel([1.3, 2.2, 0.0]).unwrap();
    let b = persp.to_pixel([3.55, 0.7, 0.0]).unwrap();
    assert!((a[2] - 8.0).abs() < 1e-12);
    let cases = [(Camera::Ortho(ortho), rx, ry), (Camera::Perspective(persp), [a[0], b[0]], [a[1], b[1]])];
    for (cam, x, y) in cases {
        let (w, h) = (cam.width(), cam.height());
        assert!(far_from_edges(w, h, x, y), "test geometry puts no pixel centre on an edge");
        let mut c = cam.canvas([0.0; 4]).unwrap();
        let stats = render_mesh(&mut c, &cam, &IDENTITY, &m, &mats, &[], &RenderOptions::default());
        let want = expected_rect(w, h, x, y);
        let got: Vec<bool> = c.color.iter().map(|p| p[3] == 1.0).collect();
        assert_eq!(got, want, "{cam:?}");
        assert_eq!(stats.fragments as usize, want.iter().filter(|&&v| v).count());
        assert!(stats.fragments > 20);
    }
}

#[test]
fn depth_is_the_distance_along_the_view_axis_and_the_nearest_wins() {
    let near_quad = quad_xy(-1.0, 1.0, -1.0, 1.0, 1.0); // 4 m from an eye at z = 5
    let far_quad = quad_xy(-3.0, 3.0, -3.0, 3.0, -3.0); // 8 m, larger on screen too
    let red = Material { base_color: [1.0, 0.0, 0.0, 1.0], ..Material::default() };
    let blue = Material { base_color: [0.0, 0.0, 1.0, 1.0], ..Material::default() };
    let cams = [Camera::Ortho(front_ortho(8.0, 48, 48)), Camera::Perspective(front_perspective(5.0, 60.0, 48, 48))];
    for cam in cams {
        // Centre of the view: ortho origin is the top-left corner, so shift the quads into view.
        let place: [[f64; 4]; 3] = match cam {
            Camera::Ortho(_) => [[1.0, 0.0, 0.0, 3.0], [0.0, 1.0, 0.0, 3.0], [0.0, 0.0, 1.0, 0.0]],
            Camera::Perspective(_) => IDENTITY,
        };
        for near_first in [true, false] {
            let mut c = cam.canvas([0.0; 4]).unwrap();
            let mut draw = |q: &Primitive, mat: &Material| {
                let mut p = q.clone();
                p.material = Some(0);
                render_mesh(
                    &mut c,
                    &cam,
                    &place,
                    &mesh(vec![p]),
                    std::slice::from_ref(mat),
                    &[],
                    &RenderOptions::default(),
                )
            };
            if near_first {
                draw(&near_quad, &red);
                draw(&far_quad, &blue);
            } else {
                draw(&far_quad, &blue);
                draw(&near_quad, &red);
            }
            let centre = (24 * 48 + 24) as usize;
            assert_eq!(c.color[centre], [1.0, 0.0, 0.0, 1.0], "{cam:?} near first: {near_first}");
            // eye/origin at z = 5 (perspective) or 10 (ortho): the near quad at z = 1
            let want = if matches!(cam, Camera::Ortho(_)) { 9.0 } else { 4.0 };
            assert!((c.depth[centre] - want).abs() < 1e-5, "{}", c.depth[centre]);
            assert!(c.color.contains(&[0.0, 0.0, 1.0, 1.0]), "far quad visible around the near one");
        }
    }
}

/// 8×8 texture: alpha 0.3 in the left half, 0.9 in the right half; colour green.
fn half_alpha_texture() -> Image {
    let mut t = Image::new(8, 8, [0.0; 4]).unwrap();
    for y in 0..8 {
        for x in 0..8 {
            t.pixels[y * 8 + x] = [0.0, 1.0, 0.0, if x < 4 { 0.3 } else { 0.9 }];
        }
    }
    t
}

#[test]
fn alpha_modes_cut_at_their_cutoff_and_write_opaque() {
    // The quad fills a 32×32 ortho canvas; its texture's alpha steps at u = ½ (with bilinear
    // filtering the step is a ramp over one texel = 4 pixels around the middle).
    let cam = Camera::Ortho(front_ortho(8.0, 32, 32));
    let m = mesh(vec![quad_xy(0.0, 4.0, 0.0, 4.0, 0.0)]);
    let tex = [half_alpha_texture()];
    let run = |mode: AlphaMode| {
        let mat = Material { base_color_texture: Some(0), alpha_mode: mode, ..Material::default() };
        let mut c = cam.canvas([0.0; 4]).unwrap();
        render_mesh(&mut c, &cam, &IDENTITY, &m, &[mat], &tex, &RenderOptions::default());
        c
    };
    for (mode, cut) in
        [(AlphaMode::Mask { cutoff: 0.5 }, 0.5), (AlphaMode::Mask { cutoff: 0.95 }, 0.95), (AlphaMode::Blend, 0.5)]
    {
        let c = run(mode);
        for y in 0..32u32 {
            for x in 0..32u32 {
                let uv = [(x as f32 + 0.5) / 32.0, (y as f32 + 0.5) / 32.0];
                let alpha = tex[0].sample_bilinear(uv)[3];
                let p = c.pixel(x, y).unwrap();
                if (alpha - cut).abs() < 1e-3 {
                    continue;
                }
                let want = if alpha >= cut { [0.0, 1.0, 0.0, 1.0] } else { [0.0; 4] };
                assert_eq!(p, want, "{mode:?} at ({x}, {y}), alpha {alpha}");
            }
        }
    }
    let c = run(AlphaMode::Mask { cutoff: 0.5 });
    assert!(c.color.iter().filter(|p| p[3] == 1.0).count() >= 32 * 13);
    assert!(c.color.iter().filter(|p| p[3] == 0.0).count() >= 32 * 13);
    // Opaque ignores alpha entirely.
    let c = run(AlphaMode::Opaque);
    assert!(c.color.iter().all(|p| p[3] == 1.0 && p[1] == 1.0));
}

#[test]
fn perspective_uv_matches_the_analytic_projection_of_a_slanted_quad() {
    // A 4 m quad leaning back 60° from the image plane, seen from 3 m: uv must follow the
    // ray-plane intersection, not the screen-linear interpolation (which is off by far more).
    let (c60, s60) = (0.5f32, 0.866_025_4f32);
    let corner = |u: f32, v: f32| [-2.0 + 4.0 * u, (0.5 - v) * 4.0 * c60, -(0.5 - v) * 4.0 * s60];
    let p = Primitive {
        positions: vec![corner(0.0, 1.0), corner(1.0, 1.0), corner(1.0, 0.0), corner(0.0, 0.0)],
        uvs: vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]],
        indices: vec![0, 1, 2, 0, 2, 3],
        material: Some(0),
        ..Primitive::default()
    };
    let view = front_perspective(3.0, 90.0, 120, 90);
    let cam = Camera::Perspective(view);
    let f = view.focal_px();
    // Ray through pixel point (px, py) from the eye (0, 0, 3) along (dx, dy, −1), hitting the
    // plane through the origin with normal (0, s60, c60); uv from the hit point.
    let analytic = |px: f64, py: f64| -> [f64; 2] {
        let d = [(px - 60.0) / f, -(py - 45.0) / f, -1.0];
        let n = [0.0, s60 as f64, c60 as f64];
        let t = -(3.0 * n[2]) / (d[1] * n[1] + d[2] * n[2]);
        let hit = [d[0] * t, d[1] * t];
        [(hit[0] + 2.0) / 4.0, 0.5 - hit[1] / (4.0 * c60 as f64)]
    };
    let mut c = cam.canvas([0.0; 4]).unwrap();
    let (mut worst, mut worst_affine, mut n) = (0.0f64, 0.0f64, 0);
    // Screen-linear uv for comparison: uv at the projected corners, interpolated on the image.
    let proj = |q: [f32; 3]| view.to_pixel(q.map(|v| v as f64)).unwrap();
    let (p0, p2) = (proj(p.positions[0]), proj(p.positions[2]));
    c.draw_camera(&cam, &IDENTITY, &p, &DrawOptions::default(), |fr| {
        let want = analytic(fr.x as f64 + 0.5, fr.y as f64 + 0.5);
        worst = worst.max((fr.uv[0] as f64 - want[0]).abs()).max((fr.uv[1] as f64 - want[1]).abs());
        // the quad's projection is a trapezoid with horizontal top and bottom: v linear in y
        let v_affine = 1.0 - (fr.y as f64 + 0.5 - p0[1]) / (p2[1] - p0[1]);
        worst_affine = worst_affine.max((v_affine - want[1]).abs());
        n += 1;
        Some([1.0; 4])
    });
    assert!(n > 2000, "{n} fragments");
    assert!(worst < 2e-4, "perspective-correct uv off by {worst}");
    assert!(worst_affine > 0.05, "the test would not notice affine interpolation ({worst_affine})");
    // And through render_mesh: a texture whose colour is its own uv (linear, so bilinear
    // sampling reproduces it exactly away from the wrap) shows the analytic uv.
    let mut ramp = Image::new(64, 64, [0.0; 4]).unwrap();
    for y in 0..64 {
        for x in 0..64 {
            ramp.pixels[y * 64 + x] = [(x as f32 + 0.5) / 64.0, (y as f32 + 0.5) / 64.0, 0.0, 1.0];
        }
    }
    let mat = Material { base_color_texture: Some(0), ..Material::default() };
    let mut c = cam.canvas([0.0; 4]).unwrap();
    render_mesh(&mut c, &cam, &IDENTITY, &mesh(vec![p]), &[mat], &[ramp], &RenderOptions::default());
    let mut checked = 0;
    for y in 0..90u32 {
        for x in 0..120u32 {
            let px = c.pixel(x, y).unwrap();
            let want = analytic(x as f64 + 0.5, y as f64 + 0.5);
            let interior = want.iter().all(|&t| t > 1.0 / 64.0 && t < 1.0 - 1.0 / 64.0);
            if px[3] == 1.0 && interior {
                checked += 1;
                assert!((px[0] as f64 - want[0]).abs() < 5e-4 && (px[1] as f64 - want[1]).abs() < 5e-4, "({x}, {y})");
            }
        }
    }
    assert!(checked > 2000);
}

#[test]
fn near_plane_clipping_draws_nothing_behind_the_eye() {
    // A floor 1 m below an eye at the origin, extending 50 m in front of and behind it. The
    // behind part, projected without clipping, would land upside down in the upper half.
    let floor = Primitive {
        positions: vec![[-50.0, -1.0, 50.0], [50.0, -1.0, 50.0], [50.0, -1.0, -50.0], [-50.0, -1.0, -50.0]],
        indices: vec![0, 1, 2, 0, 2, 3],
        material: Some(0),
        ..Primitive::default()
    };
    // Looking along −Z, horizontally.
    let view = PerspectiveView {
        eye: [0.0; 3],
        target: [0.0, 0.0, -1.0],
        up: [0.0, 1.0, 0.0],
        fov_x_deg: 90.0,
        width: 80,
        height: 60,
        near: 0.1,
    };
    let cam = Camera::Perspective(view);
    let mut c = cam.canvas([0.0; 4]).unwrap();
    let mat = Material { double_sided: true, ..Material::default() };
    let stats = render_mesh(&mut c, &cam, &IDENTITY, &mesh(vec![floor]), &[mat], &[], &RenderOptions::default());
    assert_eq!(stats.triangles, 2, "both triangles cross the near plane and are clipped, not dropped");
    assert!(c.color.iter().flatten().all(|v| v.is_finite()));
    assert!(c.depth.iter().all(|&d| d == f32::INFINITY || (d >= 0.0999 && d.is_finite())));
    let f = view.focal_px();
    for y in 0..60u32 {
        for x in 0..80u32 {
            // The ray through this pixel goes down by (y + ½ − 30)/f per metre ahead and meets the
            // floor at depth t = f / (y + ½ − 30), if it goes down, within 50 m.
            let down = (y as f64 + 0.5 - 30.0) / f;
            let side = (x as f64 + 0.5 - 40.0) / f;
            let t = if down > 0.0 { 1.0 / down } else { f64::INFINITY };
            let hits = t <= 49.0 && (side * t).abs() < 49.0;
            let misses = t > 51.0 || (side * t).abs() > 51.0;
            let covered = c.pixel(x, y).unwrap()[3] == 1.0;
            if hits {
                assert!(covered, "({x}, {y}) should see the floor");
                // exact up to the 1/256-pixel snapping: t changes by t²/f per pixel row
                let z = c.depth[(y * 80 + x) as usize] as f64;
                assert!((z - t).abs() <= t * t / f / 128.0 + 1e-4 * t, "({x}, {y}): depth {z} vs {t}");
            } else if misses {
                assert!(!covered, "({x}, {y}) sees nothing, the floor behind the eye included");
            }
        }
    }
}

/// A deterministic scatter of opaque texels with distinct colours on a transparent image.
fn sparse_image(width: u32, height: u32, every: u64) -> Image {
    let mut img = Image::new(width, height, [0.0; 4]).unwrap();
    for (k, p) in img.pixels.iter_mut().enumerate() {
        let h = verdant::random::mix64(k as u64 ^ 0x5eed);
        if h.is_multiple_of(every) {
            *p = [(h >> 8 & 255) as f32 / 255.0, (h >> 16 & 255) as f32 / 255.0, (h >> 24 & 255) as f32 / 255.0, 1.0];
        } else {
            // partly transparent, below the threshold used
            *p = [1.0, 0.0, 1.0, (h >> 32 & 255) as f32 / 255.0 * 0.4];
        }
    }
    img
}

#[test]
fn dilation_gives_every_transparent_texel_its_nearest_opaque_colour() {
    for (w, h, every) in [(61, 47, 37), (128, 9, 301), (5, 90, 23), (200, 150, 4000)] {
        let src = sparse_image(w, h, every);
        let mut img = src.clone();
        dilate(&mut img, 0.5);
        let seeds: Vec<(i64, i64, [f32; 4])> = (0..h as i64)
            .flat_map(|y| (0..w as i64).map(move |x| (x, y)))
            .filter_map(|(x, y)| {
                let p = src.pixels[(y * w as i64 + x) as usize];
                (p[3] >= 0.5).then_some((x, y, p))
            })
            .collect();
        assert!(!seeds.is_empty());
        for y in 0..h as i64 {
            for x in 0..w as i64 {
                let k = (y * w as i64 + x) as usize;
                let (before, after) = (src.pixels[k], img.pixels[k]);
                assert_eq!(after[3], before[3], "alpha unchanged");
                if before[3] >= 0.5 {
                    assert_eq!(after, before);
                    continue;
                }
                let d2 = |s: &(i64, i64, [f32; 4])| (s.0 - x).pow(2) + (s.1 - y).pow(2);
                let best = seeds.iter().map(d2).min().unwrap();
                // the colour of one of the nearest opaque texels (ties: any of them)
                assert!(
                    seeds.iter().any(|s| d2(s) == best && s.2[..3] == after[..3]),
                    "{w}×{h}: texel ({x}, {y}) got {after:?}, not a nearest opaque colour"
                );
            }
        }
    }
    // Nothing opaque: nothing to copy, the image is untouched.
    let clear = Image::new(7, 5, [0.3, 0.2, 0.1, 0.0]).unwrap();
    let mut same = clear.clone();
    dilate(&mut same, 0.5);
    assert_eq!(same, clear);
}

/// A grass-like alpha image: `blades` thin slanted blades (1.2–2.2 px wide at the root, tapering to
/// the tip) in green on transparent texels, with anti-aliased alpha (4×4 samples per texel, as a
/// supersampled bake gives) and colours dilated as a bake would.
fn grass_image(size: u32, blades: u64) -> Image {
    let ss = 4u32;
    let fine = size * ss;
    let mut img = Image::new(fine, fine, [0.0; 4]).unwrap();
    let s = size as f64;
    for b in 0..blades {
        let h = verdant::random::mix64(b ^ 0x67_7261_7373);
        let u = |shift: u32| ((h >> shift) & 0xffff) as f64 / 65535.0;
        let root = u(0) * s;
        let height = (0.4 + 0.55 * u(16)) * s;
        let lean = (u(32) - 0.5) * 0.8;
        let width = 1.2 + 1.0 * u(48);
        for y in 0..fine {
            let py = (y as f64 + 0.5) / ss as f64;
            let t = (s - py) / height; // 0 at the root (bottom), 1 at the tip
            if !(0.0..=1.0).contains(&t) {
                continue;
            }
            let centre = root + lean * t * height;
            let half = 0.5 * width * (1.0 - t);
            for x in 0..fine {
                if ((x as f64 + 0.5) / ss as f64 - centre).abs() <= half {
                    img.pixels[(y * fine + x) as usize] = [0.1, 0.3 + 0.4 * t as f32, 0.05, 1.0];
                }
            }
        }
    }
    let mut img = resolve_supersampled(&img, ss);
    dilate(&mut img, 0.5 / 255.0);
    img
}

#[test]
fn coverage_preserving_mips_keep_grass_coverage_where_box_mips_lose_it() {
    let cutoff = 0.75;
    let img = grass_image(256, 120);
    let chain = mip_chain(&img, cutoff);
    // Level 0 is the image with alpha in 8-bit steps, as its PNG holds it.
    let target = chain[0].coverage;
    assert!((target - coverage(&img, cutoff)).abs() < 0.05);
    assert!(target > 0.05 && target < 0.6, "test image coverage {target}");
    let sizes: Vec<u32> = chain.iter().map(|l| l.image.width).collect();
    assert_eq!(sizes, vec![256, 128, 64, 32, 16, 8, 4, 2, 1]);
    let boxed = box_mip_chain(&img);
    let mut box_worst = 0.0f64;
    for (k, (level, plain)) in chain.iter().zip(&boxed).enumerate() {
        let n = level.image.pixels.len() as f64;
        let box_cov = coverage(plain, cutoff);
        eprintln!(
            "level {k} {}²: coverage {:.4} (scale {:.3}), plain box {:.4}, level 0 {:.4}",
            level.image.width, level.coverage, level.alpha_scale, box_cov, target
        );
        assert_eq!(level.coverage, coverage(&level.image, cutoff));
        let rel = (level.coverage / target - 1.0).abs();
        if n >= 256.0 {
            assert!(rel <= 0.02, "level {k}: coverage {} vs {target}", level.coverage);
        } else {
            // Too few texels for 2 %: the closest texel count there is (one texel of slack for
            // ties between equal alphas).
            assert!((level.coverage - target).abs() * n <= 1.0 + 1e-9, "level {k}: {} vs {target}", level.coverage);
        }
        if k > 0 {
            box_worst = box_worst.max((box_cov / target - 1.0).abs());
            // colour stays that of the blades in every texel (dilated): no dark halo
            assert!(level.image.pixels.iter().all(|p| p[1] >= 0.29 && p[0] < 0.11), "level {k} has a halo colour");
        }
    }
    assert!(box_worst > 0.3, "plain box mips should lose coverage on thin blades ({box_worst})");
}

#[test]
fn mip_pngs_are_written_per_level_and_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let img = grass_image(64, 20);
    let chain = mip_chain(&img, 0.75);
    let paths = write_mip_pngs(dir.path(), "grass_atlas", &chain).unwrap();
    let names: Vec<String> = paths.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    assert_eq!(names[0], "grass_atlas.png");
    assert_eq!(names[1], "grass_atlas_mip1.png");
    assert_eq!(names.len(), 7);
    for (p, level) in paths.iter().zip(&chain) {
        let back = Image::read_png(p).unwrap();
        assert_eq!((back.width, back.height), (level.image.width, level.image.height));
        // alpha is stored linearly in 8 bits: coverage survives unless an alpha sits at the cutoff
        let diff = (coverage(&back, 0.75) - level.coverage).abs() * back.pixels.len() as f64;
        assert!(diff <= 2.0, "{}: {diff} texels changed side", p.display());
    }
    // no temporary files left behind
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 7);
}

fn disc(size: u32, cx: f64, cy: f64, r: f64) -> Image {
    let mut img = Image::new(size, size, [0.0; 4]).unwrap();
    for y in 0..size {
        for x in 0..size {
            let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
            if dx * dx + dy * dy <= r * r {
                img.pixels[(y * size + x) as usize] = [0.8, 0.5, 0.2, 1.0];
            }
        }
    }
    img
}

#[test]
fn compare_scores_identical_images_perfect_and_a_shifted_disc_by_its_displacement() {
    let ss = 4u32;
    let a = disc(480, 240.0, 240.0, 160.0); // 40 output pixels of radius
    let same = compare(&a, &a.clone(), 0.5, ss);
    assert_eq!((same.iou, same.color_rmse, same.edge_error_px), (1.0, 0.0, 0.0));
    // Moved by d output pixels, every outline point moves d·|cos θ| along its normal: the mean
    // displacement is 2d/π.
    for d in [1.0, 2.0, 0.5] {
        let b = disc(480, 240.0 + d * ss as f64, 240.0, 160.0);
        let e = compare(&a, &b, 0.5, ss);
        let want = 2.0 * d / std::f64::consts::PI;
        eprintln!(
            "disc shifted {d} px: edge error {:.4} px (2d/π = {want:.4}), IoU {:.4}, RMSE {:.4}",
            e.edge_error_px, e.iou, e.color_rmse
        );
        assert!((e.edge_error_px / want - 1.0).abs() < 0.05, "shift {d}: {}", e.edge_error_px);
        // IoU: the lens-shaped difference 4 r d over the area π r²
        let iou_want = 1.0 - 4.0 * 40.0 * d / (std::f64::consts::PI * 1600.0 + 2.0 * 40.0 * d);
        assert!((e.iou - iou_want).abs() < 0.01, "shift {d}: IoU {}", e.iou);
        assert!(e.color_rmse > 0.0);
    }
    // Different colour, same shape: only RMSE moves.
    let mut c = a.clone();
    c.pixels.iter_mut().filter(|p| p[3] > 0.0).for_each(|p| p[0] = 0.5);
    let e = compare(&a, &c, 0.5, 1);
    assert_eq!((e.iou, e.edge_error_px), (1.0, 0.0));
    assert!((e.color_rmse - 0.3 / 3f64.sqrt()).abs() < 1e-6, "{}", e.color_rmse);
}

/// A UV sphere of `radius` around `centre`, counter-clockwise seen from outside.
fn sphere(radius: f32, centre: [f32; 3], rings: u32, segments: u32) -> Primitive {
    let mut positions = Vec::new();
    for i in 0..=rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..=segments {
            let phi = 2.0 * std::f32::consts::PI * j as f32 / segments as f32;
            let n = [theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin()];
            positions.push([centre[0] + radius * n[0], centre[1] + radius * n[1], centre[2] + radius * n[2]]);
        }
    }
    let mut indices = Vec::new();
    let row = segments + 1;
    for i in 0..rings {
        for j in 0..segments {
            let a = i * row + j;
            let (b, c, d) = (a + 1, a + row, a + row + 1);
            indices.extend_from_slice(&[a, b, d, a, d, c]);
        }
    }
    Primitive { positions, indices, material: Some(0), ..Primitive::default() }
}

/// Crossed billboards (two vertical quads) with an alpha-masked texture: a small grass clump.
fn billboard_clump() -> (Mesh, Vec<Material>, Vec<Image>) {
    let mut a = quad_xy(-0.5, 0.5, 0.0, 0.8, 0.0);
    let mut b = a.clone();
    for p in &mut b.positions {
        *p = [p[2], p[1], -p[0]];
    }
    b.normals = vec![[1.0, 0.0, 0.0]; 4];
    a.material = Some(0);
    b.material = Some(0);
    let mat = Material {
        base_color_texture: Some(0),
        alpha_mode: AlphaMode::Mask { cutoff: 0.5 },
        double_sided: true,
        ..Material::default()
    };
    (mesh(vec![a, b]), vec![mat], vec![grass_image(64, 12)])
}

#[test]
fn lod_image_error_of_a_mesh_against_itself_passes_everywhere() {
    let (m, mats, tex) = billboard_clump();
    let r = Renderable { mesh: &m, materials: &mats, textures: &tex };
    // 3 m: the clump is larger than the canvas limit, rendered at reduced resolution (scale > 1)
    let report = lod_image_error(&r, &r, &ScreenView::default(), &[3.0, 12.0, 48.0, 192.0]);
    assert!(report.distances[0].screen_px_per_rendered_px > 1.0);
    assert_eq!(report.views, 24);
    assert_eq!(report.distances.len(), 4);
    for d in &report.distances {
        assert!(d.passes);
        assert_eq!((d.worst_iou, d.worst_color_rmse, d.worst_edge_error_px), (1.0, 0.0, 0.0), "{d:?}");
    }
    assert_eq!((report.switch_distance_m, report.never_passes, report.problem.is_none()), (0.0, false, true));
}

#[test]
fn lod_image_error_switches_a_larger_sphere_where_its_outline_moves_one_pixel() {
    // Radius 0.5 m against 0.55 m: the outline moves 0.05 m ≈ 0.05·f/d pixels, plus the 5 % of the
    // area term (ΔR(R1 + R2) / 2R1), so it reaches 1 px at about 0.0525 · 1662.8 ≈ 87 m.
    let mats = [Material::default()];
    let small = mesh(vec![sphere(0.5, [0.0, 0.5, 0.0], 24, 48)]);
    let large = mesh(vec![sphere(0.55, [0.0, 0.5, 0.0], 24, 48)]);
    let view = ScreenView::default();
    let report = lod_image_error(
        &Renderable { mesh: &small, materials: &mats, textures: &[] },
        &Renderable { mesh: &large, materials: &mats, textures: &[] },
        &view,
        &[10.0, 20.0, 40.0, 80.0, 160.0, 320.0],
    );
    for d in &report.distances {
        let expected = 0.0525 * view.focal_px() / d.distance_m;
        eprintln!(
            "{:>5} m: worst edge {:.3} px (expected ≈ {expected:.3}), mean {:.3}, worst IoU {:.4}, canvas {:?}, scale {:.2}",
            d.distance_m, d.worst_edge_error_px, d.mean_edge_error_px, d.worst_iou, d.canvas_px, d.screen_px_per_rendered_px
        );
        assert!((d.worst_edge_error_px / expected - 1.0).abs() < 0.15, "{d:?}");
    }
    eprintln!("switch distance {:.1} m", report.switch_distance_m);
    assert!(!report.never_passes);
    assert!(report.switch_distance_m > 75.0 && report.switch_distance_m < 100.0, "{}", report.switch_distance_m);
    // Only tested up to where it still fails: flagged.
    let near_only = lod_image_error(
        &Renderable { mesh: &small, materials: &mats, textures: &[] },
        &Renderable { mesh: &large, materials: &mats, textures: &[] },
        &view,
        &[10.0, 20.0],
    );
    assert!(near_only.never_passes && near_only.switch_distance_m == 20.0);
}

#[test]
fn the_chain_search_finds_for_each_level_what_a_search_of_it_alone_finds() {
    // both candidates lie inside the reference, so one framing serves all three: the rows, the
    // switch and the flag must be those of each level's own search, bit for bit
    let mats = [Material::default()];
    let reference = mesh(vec![sphere(0.55, [0.0, 0.5, 0.0], 24, 48)]);
    let fine = mesh(vec![sphere(0.54, [0.0, 0.5, 0.0], 24, 48)]);
    let coarse = mesh(vec![sphere(0.5, [0.0, 0.5, 0.0], 12, 24)]);
    let r = Renderable { mesh: &reference, materials: &mats, textures: &[] };
    let levels = [&fine, &coarse].map(|m| Renderable { mesh: m, materials: &mats, textures: &[] });
    let view = ScreenView::default();
    let opts = LodImageOptions { azimuths: 4, elevations_deg: vec![10.0, 60.0], ..LodImageOptions::default() };
    let range = SwitchSearch::from_far(640.0, 5.0, 3);
    let chain = switch_search_chain(&r, &levels.map(Candidate::Mesh), &view, &opts, &range);
    assert_eq!(chain.len(), 2);
    for (level, got) in levels.iter().zip(&chain) {
        assert_eq!(&switch_search(&r, level, &view, &opts, &range), got);
    }
    // the finer level switches in nearer; both pass far away and fail close up
    let ((_, fine_m, fine_never), (_, coarse_m, coarse_never)) = (&chain[0], &chain[1]);
    assert!(!fine_never && !coarse_never && *fine_m > 5.0 && fine_m < coarse_m, "{fine_m} {coarse_m}");
}

#[test]
fn a_search_started_midway_and_guided_finds_the_switches_the_full_search_finds() {
    // the default tree search (start at 1/8 of the far end, brackets narrowed by interpolation)
    // against halving from the far end and bisecting: the same lattice, the same switches, fewer
    // distances measured
    let mats = [Material::default()];
    let reference = mesh(vec![sphere(0.55, [0.0, 0.5, 0.0], 24, 48)]);
    let fine = mesh(vec![sphere(0.54, [0.0, 0.5, 0.0], 24, 48)]);
    let coarse = mesh(vec![sphere(0.5, [0.0, 0.5, 0.0], 12, 24)]);
    let r = Renderable { mesh: &reference, materials: &mats, textures: &[] };
    let levels = [&fine, &coarse].map(|m| Candidate::Mesh(Renderable { mesh: m, materials: &mats, textures: &[] }));
    let view = ScreenView::default();
    let opts = LodImageOptions { azimuths: 4, elevations_deg: vec![10.0, 60.0], ..LodImageOptions::default() };
    let full = switch_search_chain(&r, &levels, &view, &opts, &SwitchSearch::from_far(640.0, 5.0, 3));
    let quick = SwitchSearch { start_m: 80.0, far_m: 640.0, near_m: 5.0, bisections: 3, guided: true };
    let found = switch_search_chain(&r, &levels, &view, &opts, &quick);
    let distinct = |found: &[(Vec<verdant::bake::views::DistanceError>, f64, bool)]| {
        let mut d: Vec<u64> = found.iter().flat_map(|l| l.0.iter().map(|row| row.distance_m.to_bits())).collect();
        d.sort_unstable();
        d.dedup();
        d.len()
    };
    for (a, b) in full.iter().zip(&found) {
        assert_eq!((a.1.to_bits(), a.2), (b.1.to_bits(), b.2), "switch (m, never passes)");
    }
    assert!(
        distinct(&found) < distinct(&full),
        "{} distances, halving from the far end {}",
        distinct(&found),
        distinct(&full)
    );
    // guided, a level walks inwards to its own predicted crossings, not to another level's: a
    // near-copy of the reference (a fraction of a pixel off until close) and a crude level (its
    // switch far away) started where both pass: each level's rows, switch and flag are those of its
    // search alone, bit for bit; the near-copy is not measured at the crude level's points
    let near_copy = mesh(vec![sphere(0.549, [0.0, 0.5, 0.0], 24, 48)]);
    let crude = mesh(vec![sphere(0.4, [0.0, 0.5, 0.0], 5, 8)]);
    let pair = [&near_copy, &crude].map(|m| Renderable { mesh: m, materials: &mats, textures: &[] });
    let from_far = SwitchSearch { start_m: 640.0, ..quick };
    let both = switch_search_chain(&r, &pair.map(Candidate::Mesh), &view, &opts, &from_far);
    for (level, got) in pair.iter().zip(&both) {
        assert_eq!(&switch_search(&r, level, &view, &opts, &from_far), got);
    }
    assert!(both[0].1 < both[1].1, "the near-copy switches in nearer: {} {}", both[0].1, both[1].1);
    // a level failing at the start is followed outwards: started at 10 m, the coarse level's
    // switch is still found (the far end bounds it)
    let outward = SwitchSearch { start_m: 10.0, ..quick };
    let found = switch_search_chain(&r, &levels, &view, &opts, &outward);
    assert_eq!((found[1].1.to_bits(), found[1].2), (full[1].1.to_bits(), full[1].2));
}

#[test]
fn an_impostor_is_seen_by_each_view_through_the_card_nearest_its_azimuth() {
    // eight cards, only the first shows the reference: the three views from azimuth 0 (one per
    // elevation) match it, the other 21 see nothing
    let (m, mats, tex) = billboard_clump();
    let r = Renderable { mesh: &m, materials: &mats, textures: &tex };
    let empty = Mesh::default();
    let nothing = Renderable { mesh: &empty, materials: &[], textures: &[] };
    let cards: Vec<Renderable> = (0..8).map(|k| if k == 0 { r } else { nothing }).collect();
    let range = SwitchSearch::from_far(20.0, 20.0, 0);
    let opts = LodImageOptions::default();
    let found = switch_search_chain(&r, &[Candidate::PerAzimuth(cards)], &ScreenView::default(), &opts, &range);
    let row = &found[0].0[0];
    assert_eq!((row.worst_iou, row.mean_iou), (0.0, 3.0 / 24.0), "{row:?}");
    assert!(!row.passes && found[0].2);
}

/// A bake-like workload: four orthographic side slices and a top view of the clump, atlas,
/// dilation, mip chain, PNG bytes; plus the LoD analyzer. Everything as bytes / bits.
fn bake_fingerprint() -> (Vec<Vec<u8>>, String) {
    let (m, mats, tex) = billboard_clump();
    let mut atlas = Image::new(256, 64, [0.0; 4]).unwrap();
    for k in 0..4 {
        let a = k as f64 * std::f64::consts::FRAC_PI_4;
        let (s, c) = (a.sin(), a.cos());
        let right = [c, 0.0, -s];
        let forward = [-s, 0.0, -c];
        let view = OrthoView {
            origin: [-0.6 * right[0] - 2.0 * forward[0], 0.9, -0.6 * right[2] - 2.0 * forward[2]],
            right,
            up: [0.0, 1.0, 0.0],
            forward,
            pixels_per_metre: 64.0 / 1.2,
            width: 64,
            height: 64,
        };
        let cam = Camera::Ortho(view);
        let mut canvas = cam.canvas([0.0; 4]).unwrap();
        render_mesh(&mut canvas, &cam, &IDENTITY, &m, &mats, &tex, &RenderOptions::default());
        atlas.blit(&Image::from_canvas(&canvas), k * 64, 0);
    }
    dilate(&mut atlas, 0.5);
    let mut pngs: Vec<Vec<u8>> = mip_chain(&atlas, 0.75).iter().map(|l| l.image.encode_png().unwrap()).collect();
    let persp = Camera::Perspective(front_perspective(3.0, 40.0, 64, 64));
    let mut canvas = persp.canvas([0.0; 4]).unwrap();
    render_mesh(&mut canvas, &persp, &IDENTITY, &m, &mats, &tex, &RenderOptions::default());
    pngs.push(Image::from_canvas(&canvas).encode_png().unwrap());
    let r = Renderable { mesh: &m, materials: &mats, textures: &tex };
    let mut coarse = m.clone();
    coarse.primitives.truncate(1);
    let c = Renderable { mesh: &coarse, materials: &mats, textures: &tex };
    let report = lod_image_error(&r, &c, &ScreenView::default(), &[4.0, 16.0, 64.0]);
    (pngs, serde_json::to_string(&report).unwrap())
}

#[test]
fn bake_is_byte_identical_at_one_and_two_threads() {
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(bake_fingerprint)
    };
    let (one, two) = (run(1), run(2));
    assert!(one.0.len() > 5 && one.0.iter().all(|p| p.len() > 60));
    assert_eq!(one.0, two.0);
    assert_eq!(one.1, two.1);
    // the analyzer saw a real difference (one billboard of two is missing)
    assert!(one.1.contains("\"never_passes\""));
    assert!(!one.1.contains("\"worst_iou\":1.0,"), "{}", one.1);
}
