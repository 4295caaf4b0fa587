//! The view stage (issue 14): scene.glb as drawn from the first `[[view]]` — a tile beyond the cull
//! distance contributes no instance, a larger pixel budget switches nearer and draws fewer
//! triangles, switch distances rise with the level, the default view, bad views refused with a
//! position.

use std::path::Path;

use crate::common::*;

/// fbm 129² with 2 m cells (256 m across), 64² chunks with a two-level terrain chain, grass only
/// (the cheapest chain to measure), the given extra sections.
fn meadow(name: &str, extra: &str, grass: &str) -> String {
    format!(
        "[scene]\nname = \"{name}\"\nseed = 5\n\n[terrain]\nprocedural = {{ kind = \"fbm\", size = 129, seed = 3, relief = 30.0 }}\n\
         cell_size = 2.0\nmax_error = 0.1\nchunk = 64\nskirt = 1.0\nlods = [0.1, 0.8]\n\n[scatter]\ntile = 32.0\n\n{extra}\n\
         [[species]]\nname = \"grass\"\nkind = \"grass\"\nmax_density = 0.3\nscale = [0.8, 1.2]\n{grass}\n"
    )
}

fn build(d: &Path, name: &str, text: &str) -> serde_json::Value {
    write(d, &format!("p/{name}.toml"), text);
    ok(&verdant_in(d, &["build", &format!("p/{name}.toml"), "--out", "o"]));
    read_json(&d.join(format!("o/{name}/manifest.json")))
}

fn eye(manifest: &serde_json::Value) -> [f64; 3] {
    let e = &manifest["view"]["views"][0]["camera"]["eye"];
    [0, 1, 2].map(|k| e[k].as_f64().unwrap())
}

#[test]
fn a_tile_beyond_the_cull_distance_contributes_no_instance() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let view = "[[view]]\nname = \"corner\"\nposition = [10.0, 40.0, 10.0]\ntarget = [128.0, 10.0, 128.0]\n";
    let m = build(d, "cull", &meadow("cull", view, "cull_distance = 60.0"));
    let e = eye(&m);
    assert_eq!(m["view"]["views"][0]["camera"]["name"], "corner");
    let scene = verdant::validate::read_scene(&d.join("o/cull/scene.glb")).unwrap();
    let json = read_json(&d.join("o/cull/placements/grass.json"));
    let centre_y = m["view"]["chains"]["grass"]["centre_y_m"].as_f64().unwrap();
    // every drawn instance within 60 m (to its centre, at most centre_y·scale above its base)
    let mut drawn = Vec::new();
    for n in &scene.nodes {
        if let Some(inst) = &n.instances {
            for t in &inst.translations {
                let d2 = (t[0] as f64 - e[0]).powi(2) + (t[1] as f64 - e[1]).powi(2) + (t[2] as f64 - e[2]).powi(2);
                assert!(
                    d2.sqrt() <= 60.0 + 1.2 * centre_y.abs() + 1e-3,
                    "{}: an instance {} m from the eye",
                    n.name,
                    d2.sqrt()
                );
                drawn.push(*t);
            }
        }
    }
    // tiles whose nearest point is beyond 60 m (+ the centre offset): none of their rows is drawn
    let mut far_tiles = 0;
    for t in json["stats"]["per_tile"].as_array().unwrap() {
        let (lo, hi) = (&t["aabb_min"], &t["aabb_max"]);
        if t["count"].as_u64().unwrap() == 0 {
            continue;
        }
        let gap: f64 = (0..3)
            .map(|k| {
                let (a, b) = (lo[k].as_f64().unwrap(), hi[k].as_f64().unwrap());
                let g = if e[k] < a {
                    a - e[k]
                } else if e[k] > b {
                    e[k] - b
                } else {
                    0.0
                };
                g * g
            })
            .sum::<f64>()
            .sqrt();
        if gap > 60.0 + 2.0 {
            far_tiles += 1;
            let inside = drawn.iter().any(|p| {
                (0..3).all(|k| {
                    (p[k] as f64) >= lo[k].as_f64().unwrap() - 1e-3 && (p[k] as f64) <= hi[k].as_f64().unwrap() + 1e-3
                })
            });
            assert!(!inside, "tile {} lies beyond the cull distance but has a drawn instance", t["tile"]);
        }
    }
    assert!(far_tiles > 10, "only {far_tiles} tiles beyond the cull distance");
    let sp = &m["view"]["views"][0]["species"][0];
    assert!(sp["culled"].as_u64().unwrap() > 1000 && sp["drawn"].as_u64().unwrap() > 100, "{sp}");
    assert_eq!(sp["cull"]["distance_m"].as_f64(), Some(60.0));
    assert_eq!(sp["drawn"].as_u64().unwrap() as usize, drawn.len());
    // the table keeps every row
    assert_eq!(sp["placed"], m["scatter"]["species"][0]["count"]);
}

#[test]
fn a_larger_budget_switches_nearer_and_draws_fewer_triangles() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut runs = Vec::new();
    for (name, px) in [("fine", 1.0), ("coarse", 4.0)] {
        let m = build(d, name, &meadow(name, &format!("[lod]\nmax_pixel_error = {px}\n"), ""));
        let switch: Vec<f64> = m["view"]["chains"]["grass"]["variants"][0]
            .as_array()
            .unwrap()
            .iter()
            .map(|l| l["switch_distance_m"].as_f64().unwrap())
            .collect();
        let terrain: Vec<f64> =
            m["terrain"]["lods"].as_array().unwrap().iter().map(|l| l["switch_distance_m"].as_f64().unwrap()).collect();
        let view = &m["view"]["views"][0];
        runs.push((
            switch,
            terrain,
            view["triangles"].as_u64().unwrap(),
            view["full_detail_triangles"].as_u64().unwrap(),
        ));
    }
    let (fine, coarse) = (&runs[0], &runs[1]);
    for (s, t, _, _) in &runs {
        assert_eq!(s[0], 0.0);
        assert!(s.windows(2).all(|w| w[1] >= w[0]), "grass switch distances rise with the level: {s:?}");
        assert!(t.windows(2).all(|w| w[1] > w[0]), "terrain: {t:?}");
    }
    for k in 1..fine.0.len() {
        assert!(coarse.0[k] < fine.0[k], "grass LOD{k}: {} m at 4 px, {} m at 1 px", coarse.0[k], fine.0[k]);
    }
    assert!(coarse.1[1] < fine.1[1] / 3.0, "terrain LOD1: {} vs {}", coarse.1[1], fine.1[1]);
    assert!(coarse.2 < fine.2, "4 px draws {} triangles, 1 px {}", coarse.2, fine.2);
    assert_eq!(coarse.3, fine.3, "full detail does not depend on the budget");
    assert!(fine.2 < fine.3, "the view draws less than full detail");
}

#[test]
fn the_default_view_and_bad_views() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let m = build(d, "plain", &meadow("plain", "", ""));
    let view = &m["view"]["views"][0];
    assert_eq!(view["camera"]["name"], "view0");
    // 5 % in from the +Z edge (256 m), on the centre line, looking towards −Z
    let e = eye(&m);
    assert!((e[0] - 128.0).abs() < 1e-9 && (e[2] - (256.0 - 12.8)).abs() < 1e-9, "{e:?}");
    assert!(view["camera"]["forward"][2].as_f64().unwrap() < -0.9);
    let scene = verdant::validate::read_scene(&d.join("o/plain/scene.glb")).unwrap();
    assert_eq!(scene.extras.as_ref().unwrap()["verdant_view"]["name"], "view0");

    // both target and yaw: refused where it is written, exit 2
    write(d, "p/bad.toml", &meadow("bad", "[[view]]\ntarget = [1.0, 2.0, 3.0]\nyaw = 10.0\n", ""));
    let o = verdant_in(d, &["build", "p/bad.toml", "--out", "o"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("bad.toml:") && text(&o).contains("either `target` or `yaw`"), "{}", text(&o));
    write(d, "p/bad2.toml", &meadow("bad2", "[lod]\nmax_pixel_eror = 2.0\n", ""));
    let o = verdant_in(d, &["build", "p/bad2.toml", "--out", "o"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("did you mean `max_pixel_error`"), "{}", text(&o));
    // the eye on the target: the build fails naming the view
    write(
        d,
        "p/bad3.toml",
        &meadow("bad3", "[[view]]\nname = \"stuck\"\nposition = [5.0, 5.0, 5.0]\ntarget = [5.0, 5.0, 5.0]\n", ""),
    );
    let o = verdant_in(d, &["build", "p/bad3.toml", "--out", "o"]);
    assert_ne!(o.status.code(), Some(0));
    assert!(text(&o).contains("view `stuck`"), "{}", text(&o));
}

#[test]
fn preset_check_warns_before_any_work_when_a_species_may_exceed_max_instances() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/dense.toml", &meadow("dense", "", "max_instances = 1000"));
    let o = verdant_in(d, &["preset", "check", "p/dense.toml"]);
    assert_eq!(o.status.code(), Some(0), "a warning, not an error: {}", text(&o));
    let t = text(&o);
    // 0.3 per m² over 256 m × 256 m ≈ 19 661
    assert!(
        t.contains("warning:")
            && t.contains("species `grass` may place up to ~19661")
            && t.contains("max_instances 1000"),
        "{t}"
    );
    // positioned at the species' max_density, the figure the estimate comes from
    let preset = std::fs::read_to_string(d.join("p/dense.toml")).unwrap();
    let line = 1 + preset.lines().position(|l| l.starts_with("max_density")).unwrap();
    assert!(t.contains(&format!("p/dense.toml:{line}:1: species `grass`")), "{t}");
    write(d, "p/ok.toml", &meadow("fine", "", ""));
    assert!(!text(&verdant_in(d, &["preset", "check", "p/ok.toml"])).contains("warning"));
}

#[test]
fn output_bytes_are_in_the_manifest_and_the_report() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let m = build(d, "sizes", &meadow("sizes", "", ""));
    let listed: u64 = m["files"].as_array().unwrap().iter().map(|f| f["bytes"].as_u64().unwrap()).sum();
    assert_eq!(m["bytes"]["total"].as_u64(), Some(listed));
    let parts: u64 = m["bytes"]["by_part"].as_object().unwrap().values().map(|v| v.as_u64().unwrap()).sum();
    assert_eq!(parts, listed);
    assert_eq!(m["bytes"]["by_part"]["scene.glb"].as_u64(), m["view"]["bytes"].as_u64());
    let md = std::fs::read_to_string(d.join("o/sizes/report.md")).unwrap();
    assert!(md.contains("## Output") && md.contains(&format!("{:.1} MB in all", listed as f64 / 1e6)), "{md}");
    let r = read_json(&d.join("o/sizes/report.json"));
    assert_eq!(r["bytes"]["total"].as_u64(), Some(listed));
}

#[test]
fn the_preview_is_the_first_view_and_full_detail_can_be_compared() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/cmp.toml", &meadow("cmp", "", ""));
    ok(&verdant_in(d, &["build", "p/cmp.toml", "--out", "o", "--compare-full-detail"]));
    let r = read_json(&d.join("o/cmp/report.json"));
    let img = &r["stages"]["view"]["views"][0]["image"];
    let differing = img["differing"].as_f64().unwrap_or_else(|| panic!("no comparison: {img}"));
    assert!(img["skipped"].is_null() && (0.0..=1.0).contains(&differing), "{img}");
    assert!(img["color_rmse"].as_f64().unwrap().is_finite());
    // LoD changes what is drawn but the picture stays close: well under a tenth of the pixels
    assert!(differing < 0.1, "{differing}");
    // pixels resolved from 4 × 4 samples; the share of single samples beside it
    assert_eq!(img["samples_per_pixel"].as_u64(), Some(16), "{img}");
    assert_eq!(img["size_px"], serde_json::json!([960, 540]), "{img}");
    let samples = img["differing_samples"].as_f64().unwrap();
    assert!((0.0..0.1).contains(&samples) && samples > 0.0, "{img}");
    // preview.png: the perspective render, not the map; the map beside it
    let preview = image::open(d.join("o/cmp/preview.png")).unwrap().to_rgba8();
    assert_eq!(preview.dimensions(), (1280, 720));
    let sky = preview.get_pixel(640, 2).0;
    assert!(sky[2] > sky[0] && sky[2] > 180, "the top of the view is sky: {sky:?}");
    assert!(d.join("o/cmp/map.png").is_file());
    let md = std::fs::read_to_string(d.join("o/cmp/report.md")).unwrap();
    assert!(md.contains("Image against full detail") && md.contains("16 samples per pixel"), "{md}");
    // without the flag: no comparison
    ok(&verdant_in(d, &["build", "p/cmp.toml", "--out", "o2"]));
    assert!(read_json(&d.join("o2/cmp/report.json"))["stages"]["view"]["views"][0]["image"].is_null());
}

#[test]
fn the_view_stage_alone_says_it_needs_the_placements() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "p/v.toml", &meadow("v", "", ""));
    let o = verdant_in(d, &["build", "p/v.toml", "--only", "terrain,view", "--out", "o"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("select the scatter stage too"), "{}", text(&o));
}
