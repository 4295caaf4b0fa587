//! The command line as a user meets it: help, exit codes, no output on bad input, reports,
//! determinism across thread counts, and re-import of what was written.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use image::{ImageBuffer, Luma};
use serde_json::Value;

fn verdant(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_verdant")).args(args).output().expect("run verdant")
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

fn write_gray16(path: &Path, w: u32, h: u32, f: impl Fn(u32, u32) -> u16) {
    ImageBuffer::from_fn(w, h, |i, j| Luma([f(i, j)])).save(path).unwrap();
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn help_explains_options_with_units_and_defaults() {
    let o = verdant(&["terrain", "--help"]);
    assert!(o.status.success());
    let t = text(&o);
    for needle in [
        "--max-error",
        "METRES",
        "[default: 1]",
        "--cell-size",
        "--encoding",
        "terrain-rgb",
        "--chunk",
        "--skirt",
        "--base",
        "--report",
        "--sweep",
        "--max-samples",
    ] {
        assert!(t.contains(needle), "{needle:?} missing from help:\n{t}");
    }
    let v = verdant(&["--version"]);
    assert!(v.status.success() && text(&v).contains(env!("CARGO_PKG_VERSION")));
}

#[test]
fn bad_inputs_exit_2_name_the_file_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("empty.png"), b"").unwrap();
    std::fs::write(d.join("text.png"), b"hello, not a png").unwrap();
    write_gray16(&d.join("good.png"), 40, 40, |i, j| (i * j) as u16);
    let full = std::fs::read(d.join("good.png")).unwrap();
    std::fs::write(d.join("truncated.png"), &full[..full.len() / 2]).unwrap();
    write_gray16(&d.join("line.png"), 1, 30, |_, j| j as u16);
    write_gray16(&d.join("one.png"), 1, 1, |_, _| 7);
    let cases: &[(&str, &[&str], &str)] = &[
        ("empty.png", &[], "empty"),
        ("text.png", &[], "not a recognised image"),
        ("truncated.png", &[], "decode"),
        ("missing.png", &[], "cannot read"),
        ("line.png", &[], "2×2"),
        ("one.png", &[], "2×2"),
        ("good.png", &["--max-samples", "1000"], "--max-samples"),
        ("good.png", &["--cell-size", "-3"], "--cell-size"),
        ("good.png", &["--max-error", "-1"], "--max-error"),
        ("good.png", &["--chunk", "1"], "chunk"),
    ];
    for (name, extra, needle) in cases {
        let input = d.join(name);
        let out = d.join(format!("{name}.glb"));
        let report = d.join(format!("{name}.json"));
        let mut args = vec!["terrain", p(&input), "-o", p(&out), "--report", p(&report)];
        args.extend_from_slice(extra);
        let o = verdant(&args);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{name} {extra:?}: {t}");
        assert!(t.contains(needle), "{name} {extra:?}: {needle:?} not in {t}");
        if *name != "good.png" || extra.is_empty() {
            assert!(t.contains(name), "{name}: the message does not name the file: {t}");
        }
        assert!(!t.contains("panicked"), "{t}");
        assert!(!out.exists() && !report.exists(), "{name}: output written on bad input");
    }
    let leftovers: Vec<_> = std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(leftovers.len(), 6, "no temporary files left behind: {leftovers:?}");
}

#[test]
fn usage_errors_exit_2() {
    assert_eq!(verdant(&["terrain"]).status.code(), Some(2));
    assert_eq!(verdant(&["terrain", "--demo", "--mode", "cubes"]).status.code(), Some(2));
    assert_eq!(verdant(&["terrain", "x.r16", "--size", "12"]).status.code(), Some(2));
}

/// An output the writers cannot make (`-o p.txt`, no file name) is refused before any work, as bad
/// input: the message is about the output even when the input is missing too (it was checked
/// first), and nothing is written.
#[test]
fn an_unwritable_output_name_is_refused_first_with_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let missing = d.join("missing.png");
    let cases: [(&str, Vec<&str>); 3] = [
        ("terrain", vec!["terrain", p(&missing)]),
        ("tree", vec!["tree", "builtin:conifer"]),
        ("mesh", vec!["mesh", "missing.obj"]),
    ];
    for (name, args) in cases {
        let out = d.join(format!("{name}.txt"));
        let mut args = args.clone();
        args.extend(["-o", p(&out)]);
        let o = verdant(&args);
        let t = String::from_utf8_lossy(&o.stderr).to_string();
        assert_eq!(o.status.code(), Some(2), "{name}: {t}");
        assert!(t.contains("unknown extension \"txt\"") && t.contains(&format!("{name}.txt")), "{name}: {t}");
        assert!(!t.contains("missing"), "{name}: the input was read before the output was checked: {t}");
    }
    assert_eq!(std::fs::read_dir(d).unwrap().count(), 0, "nothing is written");
}

#[test]
fn demo_terrain_report_and_reimport() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo.glb");
    let report = dir.path().join("demo.json");
    let o = verdant(&["terrain", "--demo", "--max-error", "2", "-o", p(&out), "--report", p(&report)]);
    assert!(o.status.success(), "{}", text(&o));
    let r = read_json(&report);
    for key in [
        "input",
        "width",
        "height",
        "encoding",
        "mode",
        "max_error_requested",
        "max_error",
        "rms_error",
        "vertices",
        "triangles",
    ] {
        assert!(!r[key].is_null(), "report lacks {key}: {r}");
    }
    for key in ["decode", "mesh", "export", "total"] {
        assert!(r["seconds"][key].as_f64().is_some(), "report lacks seconds.{key}");
    }
    assert_eq!(r["mode"], "tin");
    assert!(r["max_error"].as_f64().unwrap() <= 2.0);
    assert!(r["triangles"].as_u64().unwrap() < r["full_grid_triangles"].as_u64().unwrap() / 4);
    let v = verdant(&["validate", p(&out), "--up-facing"]);
    assert!(v.status.success(), "{}", text(&v));
}

#[test]
fn same_output_bytes_for_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    for threads in ["1", "2", "4"] {
        let out = dir.path().join(format!("t{threads}.glb"));
        let o = verdant(&[
            "--threads",
            threads,
            "--quiet",
            "terrain",
            "--demo",
            "--max-error",
            "1",
            "--chunk",
            "64",
            "-o",
            p(&out),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        assert!(o.stdout.is_empty(), "--quiet prints nothing");
        files.push(std::fs::read(out).unwrap());
    }
    assert!(files.windows(2).all(|w| w[0] == w[1]), "outputs differ between thread counts");
}

#[test]
fn sweep_prints_the_speed_error_curve() {
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("sweep.json");
    let o = verdant(&["terrain", "--demo", "--sweep", "30,10,3,1", "--report", p(&report)]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("measured_max_m") && t.contains("triangles"), "{t}");
    let rows = read_json(&report);
    let rows = rows.as_array().unwrap();
    assert_eq!(rows.len(), 4);
    let mut last = 0;
    for r in rows {
        assert!(r["max_error"].as_f64().unwrap() <= r["max_error_requested"].as_f64().unwrap());
        let tris = r["triangles"].as_u64().unwrap();
        assert!(tris >= last, "finer bound, more triangles");
        last = tris;
    }
}

#[test]
fn grid_step_one_reproduces_the_heightmap() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("h.png");
    write_gray16(&input, 31, 17, |i, j| ((i * 977 + j * 131) % 65536) as u16);
    let out = dir.path().join("h.obj");
    let report = dir.path().join("h.json");
    let o = verdant(&[
        "terrain",
        p(&input),
        "--mode",
        "grid",
        "--height-scale",
        "65535",
        "-o",
        p(&out),
        "--report",
        p(&report),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let r = read_json(&report);
    assert_eq!(r["max_error"].as_f64(), Some(0.0));
    assert_eq!(r["triangles"].as_u64(), Some(2 * 30 * 16));
    assert!(PathBuf::from(format!("{}", dir.path().join("h.mtl").display())).exists());
    assert!(verdant(&["validate", p(&out), "--up-facing"]).status.success());
}

#[test]
fn validate_fails_on_a_broken_file() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 2 9\n").unwrap();
    let o = verdant(&["validate", p(&bad)]);
    assert_ne!(o.status.code(), Some(0), "{}", text(&o));
    let missing = dir.path().join("nope.glb");
    let o = verdant(&["validate", p(&missing)]);
    assert_ne!(o.status.code(), Some(0));
    assert!(text(&o).contains("nope.glb"));
}
