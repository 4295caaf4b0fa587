use super::*;
use crate::mesh::Primitive;

/// A view where world x, y map to pixel x, y one to one (y down), depth = world z.
fn identity() -> Projection {
    Projection { rows: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]] }
}

fn prim(positions: Vec<[f32; 3]>, indices: Vec<u32>) -> Primitive {
    Primitive { positions, indices, ..Primitive::default() }
}

/// Counts how often each pixel is written.
fn coverage(c: &mut Canvas, p: &Primitive, opts: &DrawOptions) -> Vec<u32> {
    let mut counts = vec![0u32; c.color.len()];
    let w = c.width as usize;
    c.draw(&identity(), p, opts, |f| {
        counts[f.y as usize * w + f.x as usize] += 1;
        Some([1.0; 4])
    });
    counts
}

const NO_DEPTH: DrawOptions = DrawOptions { cull: Cull::None, depth_test: false, depth_write: false };

#[test]
fn quad_covers_exactly_its_pixels_once() {
    // Pixel-aligned quad [2, 6) × [1, 4): pixel centres 2.5..5.5 × 1.5..3.5 → 4×3 pixels.
    let p = prim(vec![[2.0, 1.0, 0.0], [6.0, 1.0, 0.0], [6.0, 4.0, 0.0], [2.0, 4.0, 0.0]], vec![0, 1, 2, 0, 2, 3]);
    let mut c = Canvas::new(8, 6, [0.0; 4]).unwrap();
    let counts = coverage(&mut c, &p, &NO_DEPTH);
    for y in 0..6 {
        for x in 0..8 {
            let inside = (2..6).contains(&x) && (1..4).contains(&y);
            assert_eq!(counts[y * 8 + x], inside as u32, "pixel ({x}, {y})");
        }
    }
}

#[test]
fn shared_edges_through_pixel_centres_are_drawn_once() {
    // A jittered grid whose vertices sit on pixel centres and edges pass through many centres:
    // the worst case for the fill rule. Every pixel centre inside the hull is written once.
    let n = 6usize;
    let s = 7.0f32;
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let inner = i > 0 && i < n && j > 0 && j < n;
            let jit = if inner { ((i * 3 + j * 5) % 5) as f32 - 2.0 } else { 0.0 };
            pos.push([0.5 + i as f32 * s + jit, 0.5 + j as f32 * s - jit, 0.0]);
        }
    }
    let mut idx = Vec::new();
    for j in 0..n as u32 {
        for i in 0..n as u32 {
            let a = j * (n as u32 + 1) + i;
            let (b, c, d) = (a + 1, a + n as u32 + 1, a + n as u32 + 2);
            // alternate the diagonal, and the winding, to exercise both orientations
            if (i + j) % 2 == 0 {
                idx.extend_from_slice(&[a, b, d, a, d, c]);
            } else {
                idx.extend_from_slice(&[a, c, b, b, c, d]);
            }
        }
    }
    let p = prim(pos, idx);
    let side = (n as f32 * s + 1.0) as u32;
    let mut c = Canvas::new(side, side, [0.0; 4]).unwrap();
    let counts = coverage(&mut c, &p, &NO_DEPTH);
    // Hull is [0.5, 0.5 + n·s]²: pixel centres x + 0.5 with 0 ≤ x ≤ n·s; the right and bottom
    // borders are not top-left edges, so x = n·s is outside.
    let last = (n as f32 * s) as usize;
    for y in 0..side as usize {
        for x in 0..side as usize {
            let expect = (x < last && y < last) as u32;
            assert_eq!(counts[y * side as usize + x], expect, "pixel ({x}, {y})");
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    /// Random jittered triangulations of a rectangle (sub-pixel vertices, random diagonals and
    /// windings): every pixel centre of the rectangle is written exactly once, nothing else.
    #[test]
    fn random_triangulations_cover_each_pixel_once(
        jitter in proptest::collection::vec((-300i32..=300, -300i32..=300), 64),
        flips in proptest::collection::vec(0u8..4, 49),
    ) {
        let (n, s) = (7usize, 5.0f32);
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let inner = i > 0 && i < n && j > 0 && j < n;
                let (dx, dy) = if inner { jitter[j * 8 + i] } else { (0, 0) };
                // jitter up to ±1.17 px in 1/256 steps (cells stay convex, so either diagonal is a valid
                // split): vertices land on centres, on edges, anywhere
                pos.push([0.5 + i as f32 * s + dx as f32 / 256.0, 0.5 + j as f32 * s + dy as f32 / 256.0, 0.0]);
            }
        }
        let mut idx = Vec::new();
        for j in 0..n as u32 {
            for i in 0..n as u32 {
                let a = j * (n as u32 + 1) + i;
                let (b, c, d) = (a + 1, a + n as u32 + 1, a + n as u32 + 2);
                let f = flips[j as usize * n + i as usize];
                let mut two = if f & 1 == 0 { [a, b, d, a, d, c] } else { [a, b, c, b, d, c] };
                if f & 2 != 0 {
                    two.swap(1, 2);
                }
                idx.extend_from_slice(&two);
            }
        }
        let p = prim(pos, idx);
        let side = (n as f32 * s + 2.0) as u32;
        let mut c = Canvas::new(side, side, [0.0; 4]).unwrap();
        let counts = coverage(&mut c, &p, &NO_DEPTH);
        let last = (n as f32 * s) as usize;
        for y in 0..side as usize {
            for x in 0..side as usize {
                proptest::prop_assert_eq!(counts[y * side as usize + x], (x < last && y < last) as u32, "pixel ({}, {})", x, y);
            }
        }
    }
}

#[test]
fn fan_around_a_pixel_centre_owns_it_once() {
    // Eight triangles around the centre of pixel (8, 8), with diagonal and axis edges.
    let c0 = [8.5f32, 8.5];
    let ring: Vec<[f32; 2]> = (0..8)
        .map(|k| {
            let d = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)][k];
            [c0[0] + 6.0 * d.0 as f32, c0[1] + 6.0 * d.1 as f32]
        })
        .collect();
    let mut pos = vec![[c0[0], c0[1], 0.0]];
    pos.extend(ring.iter().map(|r| [r[0], r[1], 0.0]));
    let mut idx = Vec::new();
    for k in 0..8u32 {
        idx.extend_from_slice(&[0, 1 + k, 1 + (k + 1) % 8]);
    }
    let p = prim(pos, idx);
    let mut c = Canvas::new(17, 17, [0.0; 4]).unwrap();
    let counts = coverage(&mut c, &p, &NO_DEPTH);
    assert_eq!(counts[8 * 17 + 8], 1);
    assert!(counts.iter().all(|&n| n <= 1));
}

#[test]
fn depth_test_keeps_the_nearest() {
    let quad = |z: f32| vec![[0.0, 0.0, z], [4.0, 0.0, z], [4.0, 4.0, z], [0.0, 4.0, z]];
    let idx = vec![0, 1, 2, 0, 2, 3];
    let mut c = Canvas::new(4, 4, [0.0; 4]).unwrap();
    let opts = DrawOptions::default();
    c.draw(&identity(), &prim(quad(5.0), idx.clone()), &opts, |_| Some([1.0, 0.0, 0.0, 1.0]));
    let s = c.draw(&identity(), &prim(quad(9.0), idx.clone()), &opts, |_| Some([0.0, 1.0, 0.0, 1.0]));
    assert_eq!(s.fragments, 0, "farther quad hidden");
    c.draw(&identity(), &prim(quad(2.0), idx), &opts, |_| Some([0.0, 0.0, 1.0, 1.0]));
    assert!(c.color.iter().all(|&p| p == [0.0, 0.0, 1.0, 1.0]));
    assert!(c.depth.iter().all(|&d| d == 2.0));
}

#[test]
fn interpolation_is_exact_at_vertices_and_linear_between() {
    // Vertices on pixel centres; attribute = a linear function of position.
    let pos = vec![[0.5, 0.5, 1.0], [8.5, 0.5, 2.0], [0.5, 8.5, 3.0]];
    let f = |p: [f32; 3]| [p[0] * 0.25 + 1.0, p[1] * -0.5 + 3.0];
    let mut p = prim(pos.clone(), vec![0, 1, 2]);
    p.uvs = pos.iter().map(|&q| f(q)).collect();
    p.colors = vec![[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0]];
    let mut c = Canvas::new(10, 10, [0.0; 4]).unwrap();
    let mut frags = Vec::new();
    c.draw(&identity(), &p, &DrawOptions::default(), |fr| {
        frags.push(*fr);
        Some([1.0; 4])
    });
    let at = |x: u32, y: u32| frags.iter().find(|fr| fr.x == x && fr.y == y).copied();
    // Vertex 0 and the top-left-owned vertices are exact; vertex 1 and 2 lie on the non-top-left
    // hypotenuse, which the fill rule hands to the neighbour.
    let v0 = at(0, 0).expect("vertex 0 covered");
    assert_eq!(v0.uv, p.uvs[0]);
    assert_eq!(v0.color, p.colors[0]);
    assert_eq!(v0.bary, [1.0, 0.0, 0.0]);
    assert_eq!(v0.depth, 1.0);
    for fr in &frags {
        let want = f([fr.x as f32 + 0.5, fr.y as f32 + 0.5, 0.0]);
        assert!((fr.uv[0] - want[0]).abs() < 1e-5 && (fr.uv[1] - want[1]).abs() < 1e-5);
        assert!((fr.bary.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        assert!((fr.position[0] - (fr.x as f32 + 0.5)).abs() < 1e-5);
    }
    // Reversed winding: vertex 0 still exact, bary still in index order.
    let mut q = p.clone();
    q.indices = vec![0, 2, 1];
    let mut c2 = Canvas::new(10, 10, [0.0; 4]).unwrap();
    let mut first = None;
    c2.draw(&identity(), &q, &DrawOptions::default(), |fr| {
        if fr.x == 0 && fr.y == 0 {
            first = Some(*fr);
        }
        Some([1.0; 4])
    });
    let f0 = first.expect("covered");
    assert_eq!(f0.bary, [1.0, 0.0, 0.0]);
    assert_eq!(f0.uv, p.uvs[0]);
}

#[test]
fn culling_by_facing_on_the_image() {
    // Counter-clockwise on the image (y down): (0,0) → (0,4) → (4,0).
    let ccw = prim(vec![[0.0, 0.0, 0.0], [0.0, 4.0, 0.0], [4.0, 0.0, 0.0]], vec![0, 1, 2]);
    let mut cw = ccw.clone();
    cw.indices = vec![0, 2, 1];
    let mut c = Canvas::new(4, 4, [0.0; 4]).unwrap();
    let back = DrawOptions { cull: Cull::Back, ..DrawOptions::default() };
    let s = c.draw(&identity(), &ccw, &back, |f| {
        assert!(f.front_facing);
        Some([1.0; 4])
    });
    assert_eq!((s.triangles, s.culled), (1, 0));
    let s = c.draw(&identity(), &cw, &back, |_| Some([1.0; 4]));
    assert_eq!((s.triangles, s.culled), (0, 1));
}

#[test]
fn bad_input_is_skipped_not_panicked() {
    let p = prim(
        vec![[0.0, 0.0, 0.0], [f32::NAN, 1.0, 0.0], [3.0, 3.0, 0.0], [1e30, 0.0, 0.0]],
        vec![0, 1, 2, 0, 2, 9, 0, 2, 3, 0, 0, 2, 7],
    );
    let mut c = Canvas::new(4, 4, [0.0; 4]).unwrap();
    let s = c.draw(&identity(), &p, &DrawOptions::default(), |_| Some([1.0; 4]));
    assert_eq!((s.triangles, s.culled, s.skipped, s.fragments), (0, 1, 3, 0));
    assert!(Canvas::new(0, 5, [0.0; 4]).is_err());
    assert!(Canvas::new(MAX_CANVAS_SIDE + 1, 5, [0.0; 4]).is_err());
}

fn test_mesh() -> Primitive {
    // A 40×40 grid of wavy quads spanning the canvas and beyond, overlapping itself twice.
    let n = 40u32;
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f32 * 2.7 - 4.0, j as f32 * 2.3 - 3.0);
            pos.push([x + (y * 0.7).sin(), y + (x * 0.3).cos(), (x * 0.1).sin() + (y * 0.2).cos()]);
        }
    }
    let mut idx = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            idx.extend_from_slice(&[a, a + 1, a + n + 2, a, a + n + 2, a + n + 1]);
        }
    }
    let mut p = prim(pos, idx.clone());
    // a second, shifted copy so the depth test has work to do
    let off = p.positions.len() as u32;
    let shifted: Vec<[f32; 3]> = p.positions.iter().map(|q| [q[0] + 1.3, q[1] - 0.7, q[2] + 0.05]).collect();
    p.positions.extend(shifted);
    p.indices.extend(idx.iter().map(|i| i + off));
    p.colors = p.positions.iter().map(|q| [q[0] / 100.0, q[1] / 100.0, q[2], 1.0]).collect();
    p
}

#[test]
fn parallel_equals_serial_and_is_deterministic() {
    let p = test_mesh();
    let shade = |f: &Fragment| Some(f.color);
    let mut a = Canvas::new(97, 83, [0.0; 4]).unwrap();
    let sa = a.draw(&identity(), &p, &DrawOptions::default(), shade);
    let mut b = Canvas::new(97, 83, [0.0; 4]).unwrap();
    let sb = b.draw_par(&identity(), &p, &DrawOptions::default(), shade);
    assert_eq!(sa, sb);
    assert_eq!(a, b);
    let mut c = Canvas::new(97, 83, [0.0; 4]).unwrap();
    c.draw_par(&identity(), &p, &DrawOptions::default(), shade);
    assert_eq!(b.encode_png().unwrap(), c.encode_png().unwrap());
    assert!(sa.fragments > 0);
}

#[test]
fn discarded_fragments_leave_colour_and_depth() {
    let p = prim(vec![[0.0, 0.0, 1.0], [4.0, 0.0, 1.0], [4.0, 4.0, 1.0], [0.0, 4.0, 1.0]], vec![0, 1, 2, 0, 2, 3]);
    let mut c = Canvas::new(4, 4, [0.5; 4]).unwrap();
    let s = c.draw(&identity(), &p, &DrawOptions::default(), |f| (f.x % 2 == 0).then_some([1.0; 4]));
    assert_eq!(s.fragments, 8);
    assert_eq!(c.pixel(1, 0), Some([0.5; 4]));
    assert_eq!(c.depth[1], f32::INFINITY);
    assert_eq!(c.pixel(0, 0), Some([1.0; 4]));
}

/// A ground grid of `n`×`n` cells over [−half, half]² at y = 0, diagonals alternating.
fn ground(n: u32, half: f32) -> Primitive {
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let t = |k: u32| -half + 2.0 * half * k as f32 / n as f32;
            pos.push([t(i), 0.0, t(j)]);
        }
    }
    let mut idx = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            let (b, c, d) = (a + 1, a + n + 1, a + n + 2);
            // counter-clockwise seen from +Y
            if (i + j) % 2 == 0 {
                idx.extend_from_slice(&[a, c, d, a, d, b]);
            } else {
                idx.extend_from_slice(&[a, c, b, b, c, d]);
            }
        }
    }
    prim(pos, idx)
}

const IDENTITY: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];

fn low_camera() -> PerspectiveView {
    // 1 m above a ground that runs under and behind the eye, looking slightly down.
    PerspectiveView {
        eye: [0.3, 1.0, 0.2],
        target: [0.0, 0.2, -6.0],
        up: [0.0, 1.0, 0.0],
        fov_x_deg: 100.0,
        width: 96,
        height: 64,
        near: 0.05,
    }
}

#[test]
fn perspective_ground_through_the_near_plane_is_watertight_and_exact() {
    // 2 km of ground in 40 m cells: most cells cross the near plane or the guard band, so
    // clipping makes every visible pixel; each must be written once, exactly where the ray
    // from the eye through its centre hits the ground in front of the near plane.
    let v = low_camera();
    let p = ground(50, 1000.0);
    let cam = Camera::Perspective(v);
    let mut c = cam.canvas([0.0; 4]).unwrap();
    let mut counts = vec![0u32; c.color.len()];
    let mut depths = vec![f32::NAN; c.color.len()];
    let w = v.width as usize;
    let s = c.draw_camera(&cam, &IDENTITY, &p, &NO_DEPTH, |f| {
        counts[f.y as usize * w + f.x as usize] += 1;
        depths[f.y as usize * w + f.x as usize] = f.depth;
        assert!(f.bary.iter().all(|b| b.is_finite()) && f.position.iter().all(|q| q.is_finite()));
        Some([1.0; 4])
    });
    assert_eq!(s.skipped, 0);
    assert!(s.clipped > 0, "part of the ground is behind the eye");
    let frame = v.frame().unwrap();
    let [r, u, fw] = frame.view.rows.map(|row| [row[0], row[1], row[2]]);
    let mut checked = 0;
    // The ray from the eye through pixel point (px, py) meets the ground at view depth t (the ray
    // parameter, its forward component being 1) and at (x, z).
    let ray = |px: f64, py: f64| {
        let (dx, dy) = ((px - frame.centre[0]) / frame.focal_px, -(py - frame.centre[1]) / frame.focal_px);
        let dir = [0, 1, 2].map(|k| fw[k] + dx * r[k] + dy * u[k]);
        let t = if dir[1] < 0.0 { -v.eye[1] / dir[1] } else { f64::INFINITY };
        (t, [v.eye[0] + t * dir[0], v.eye[2] + t * dir[2]], dir)
    };
    for y in 0..v.height as usize {
        for x in 0..w {
            let (t, hit, dir) = ray(x as f64 + 0.5, y as f64 + 0.5);
            let inside = t.is_finite() && hit[0].abs() < 1000.0 && hit[1].abs() < 1000.0;
            let margin = |a: f64| (a.abs() - 1000.0).abs() > 1.0 && dir[1].abs() > 1e-4;
            if !(margin(hit[0]) && margin(hit[1])) {
                continue;
            }
            checked += 1;
            assert_eq!(counts[y * w + x], inside as u32, "pixel ({x}, {y})");
            if inside {
                // Exact up to the 1/256-pixel vertex snapping: within the depths a pixel
                // centre moved by 1/128 pixel would see (near the horizon that is metres).
                let z = depths[y * w + x] as f64;
                let e = 1.0 / 128.0;
                let around = [(-e, -e), (e, -e), (-e, e), (e, e)]
                    .map(|(ex, ey)| ray(x as f64 + 0.5 + ex, y as f64 + 0.5 + ey).0);
                let lo = around.iter().fold(t, |a, &b| a.min(b));
                let hi = around.iter().fold(t, |a, &b| a.max(b));
                assert!(
                    z >= lo * (1.0 - 1e-6) && z <= hi * (1.0 + 1e-6),
                    "pixel ({x}, {y}): depth {z} vs {t} ({lo}..{hi})"
                );
            }
        }
    }
    assert!(checked > 5000);
    assert!(counts.contains(&0) && counts.contains(&1));
}

#[test]
fn perspective_clips_what_is_behind_the_eye_and_parallel_matches_serial() {
    let v = low_camera();
    let cam = Camera::Perspective(v);
    // Entirely behind the eye (the view looks towards −Z, this is at +Z).
    let behind = prim(vec![[-1.0, 0.0, 3.0], [1.0, 0.0, 3.0], [0.0, 2.0, 3.0]], vec![0, 1, 2]);
    let mut c = cam.canvas([0.0; 4]).unwrap();
    let s = c.draw_camera(&cam, &IDENTITY, &behind, &DrawOptions::default(), |_| Some([1.0; 4]));
    assert_eq!((s.triangles, s.clipped, s.fragments), (0, 1, 0));
    // A wall through the eye's position, both windings, with colours.
    let mut wall = prim(
        vec![[-3.0, -1.0, 2.0], [3.0, -1.0, 2.0], [3.0, 3.0, -4.0], [-3.0, 3.0, -4.0]],
        vec![0, 1, 2, 0, 2, 3, 0, 2, 1],
    );
    wall.colors = vec![[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0]];
    let mut p = ground(30, 50.0);
    let off = p.positions.len() as u32;
    p.positions.extend_from_slice(&wall.positions);
    p.indices.extend(wall.indices.iter().map(|i| i + off));
    p.colors = vec![[0.5; 4]; off as usize];
    p.colors.extend_from_slice(&wall.colors);
    let shade = |f: &Fragment| Some([f.color[0], f.color[1], f.depth / 100.0, f.front_facing as u8 as f32]);
    let mut a = cam.canvas([0.0; 4]).unwrap();
    let sa = a.draw_camera(&cam, &IDENTITY, &p, &DrawOptions::default(), shade);
    let mut b = cam.canvas([0.0; 4]).unwrap();
    let sb = b.draw_camera_par(&cam, &IDENTITY, &p, &DrawOptions::default(), shade);
    assert_eq!(sa, sb);
    assert_eq!(a, b);
    assert!(a.color.iter().chain(&b.color).flatten().all(|v| v.is_finite()));
    assert!(a.depth.iter().all(|&d| d == f32::INFINITY || d >= v.near as f32 * 0.999));
    assert!(sa.fragments > 0);
}

#[test]
fn facing_agrees_between_the_cameras() {
    // Counter-clockwise seen from +Z; both cameras look from +Z towards −Z.
    let tri = prim(vec![[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]], vec![0, 1, 2]);
    let ortho = Camera::Ortho(OrthoView {
        origin: [-2.0, 2.0, 5.0],
        right: [1.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        forward: [0.0, 0.0, -1.0],
        pixels_per_metre: 8.0,
        width: 32,
        height: 32,
    });
    let persp = Camera::Perspective(PerspectiveView {
        eye: [0.0, 0.0, 5.0],
        target: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_x_deg: 45.0,
        width: 32,
        height: 32,
        near: 0.1,
    });
    for cam in [ortho, persp] {
        let back = DrawOptions { cull: Cull::Back, ..DrawOptions::default() };
        let mut c = cam.canvas([0.0; 4]).unwrap();
        let s = c.draw_camera(&cam, &IDENTITY, &tri, &back, |f| {
            assert!(f.front_facing);
            Some([1.0; 4])
        });
        assert_eq!((s.triangles, s.culled), (1, 0), "{cam:?}");
        assert!(s.fragments > 20);
        let mut rev = tri.clone();
        rev.indices = vec![0, 2, 1];
        let s = c.draw_camera(&cam, &IDENTITY, &rev, &back, |_| Some([1.0; 4]));
        assert_eq!((s.triangles, s.culled), (0, 1), "{cam:?}");
    }
}

#[test]
fn bad_perspective_views_are_errors_and_draw_nothing() {
    let good = low_camera();
    assert!(good.check().is_ok());
    let bad = [
        PerspectiveView { target: good.eye, ..good },
        PerspectiveView { up: [0.0, 0.0, 0.0], ..good },
        PerspectiveView { fov_x_deg: 180.0, ..good },
        PerspectiveView { near: 0.0, ..good },
        PerspectiveView { eye: [f64::NAN, 0.0, 0.0], ..good },
        PerspectiveView { width: 0, ..good },
    ];
    let tri = prim(vec![[-1.0, 0.0, -3.0], [1.0, 0.0, -3.0], [0.0, 2.0, -3.0]], vec![0, 1, 2]);
    for v in bad {
        assert!(v.check().is_err(), "{v:?}");
        assert!(Camera::Perspective(v).canvas([0.0; 4]).is_err());
        let mut c = Canvas::new(8, 8, [0.0; 4]).unwrap();
        let s = c.draw_camera(&Camera::Perspective(v), &IDENTITY, &tri, &DrawOptions::default(), |_| Some([1.0; 4]));
        assert_eq!((s.skipped, s.fragments), (1, 0));
    }
}

#[test]
fn ortho_view_maps_corners_and_png_roundtrips() {
    let v = OrthoView::top_down(10.0, 30.0, -5.0, 5.0, 100.0, 200);
    assert_eq!((v.width, v.height), (200, 100));
    let tl = v.to_pixel([10.0, 40.0, -5.0]);
    assert_eq!(tl, [0.0, 0.0, 60.0]);
    let br = v.to_pixel([30.0, 100.0, 5.0]);
    assert_eq!(br, [200.0, 100.0, 0.0]);
    let mut c = v.canvas([0.0, 0.0, 0.0, 0.0]).unwrap();
    c.color[0] = [1.0, 0.5, 0.0, 1.0];
    let png = c.encode_png().unwrap();
    let img = image::load_from_memory(&png).unwrap().to_rgba8();
    assert_eq!(img.dimensions(), (200, 100));
    assert_eq!(img.get_pixel(0, 0).0, [255, 188, 0, 255]);
    assert_eq!(img.get_pixel(1, 0).0, [0, 0, 0, 0]);
}

proptest::proptest! {
    /// A sphere [`PerspectiveView::sphere_test`] rejects has no point that projects into the image
    /// in front of the near plane (sampled over its surface and inside).
    #[test]
    fn a_rejected_sphere_shows_nothing(c in proptest::array::uniform3(-12.0f64..12.0), r in 0.01f64..4.0) {
        let v = low_camera();
        let sees = v.sphere_test().unwrap();
        if !sees(c, r) {
            for i in 0..200 {
                // points spread over the ball (a spiral of directions, three radii)
                let t = i as f64 * 2.399_963;
                let y = 1.0 - 2.0 * (i as f64 + 0.5) / 200.0;
                let s = (1.0 - y * y).sqrt();
                for f in [0.3, 0.7, 1.0] {
                    let p = [c[0] + f * r * s * t.cos(), c[1] + f * r * y, c[2] + f * r * s * t.sin()];
                    if let Some([x, y, _]) = v.to_pixel(p) {
                        proptest::prop_assert!(
                            !(0.0..=v.width as f64).contains(&x) || !(0.0..=v.height as f64).contains(&y),
                            "{p:?} of a rejected sphere shows at ({x}, {y})"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn spheres_in_front_are_seen_and_behind_or_aside_are_not() {
    let v = low_camera();
    let sees = v.sphere_test().unwrap();
    assert!(sees(v.target, 0.5), "on the view axis");
    let behind = [2.0 * v.eye[0] - v.target[0], 2.0 * v.eye[1] - v.target[1], 2.0 * v.eye[2] - v.target[2]];
    assert!(!sees(behind, 0.5), "behind the eye");
    assert!(sees(behind, 7.0), "behind the eye, but reaching past it");
    assert!(!sees([v.eye[0] + 40.0, v.eye[1], v.eye[2] - 3.0], 1.0), "far aside");
}
