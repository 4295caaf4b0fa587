//! Heightmap decoding: every encoding's formula, the axis contract, and clear errors on bad input.

use std::path::{Path, PathBuf};

use image::{ImageBuffer, Luma, Rgb, Rgba};
use proptest::prelude::*;
use verdant::heightfield::{decode, load, DecodeOptions, Encoding, HeightfieldError};

fn png_bytes<P: image::PixelWithColorType>(img: &ImageBuffer<P, Vec<P::Subpixel>>) -> Vec<u8>
where
    [P::Subpixel]: image::EncodableLayout,
{
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).expect("encode test png");
    out.into_inner()
}

fn opts(encoding: Encoding) -> DecodeOptions {
    DecodeOptions { encoding, ..DecodeOptions::default() }
}

fn err_text(e: HeightfieldError) -> String {
    e.to_string()
}

#[test]
fn gray8_scales_by_255() {
    let img = ImageBuffer::from_fn(3, 2, |i, j| Luma([(i * 100 + j * 10) as u8]));
    let o = DecodeOptions { height_scale_m: 51.0, height_offset_m: -5.0, cell_size_m: 2.5, ..opts(Encoding::Auto) };
    let d = decode(Path::new("a.png"), &png_bytes(&img), &o).unwrap();
    assert_eq!(d.encoding, Encoding::Gray);
    let hf = d.heightfield;
    assert_eq!((hf.width, hf.height), (3, 2));
    assert_eq!(hf.at(2, 1), (-5.0 + 210.0 / 255.0 * 51.0) as f32);
    // the axis contract: column i, row j → x = i·cell, z = j·cell
    assert_eq!(hf.position(2, 1), [5.0, hf.at(2, 1), 2.5]);
}

#[test]
fn gray16_full_range() {
    let img = ImageBuffer::from_fn(2, 2, |i, j| Luma([if (i + j) % 2 == 0 { 0u16 } else { 65535 }]));
    let o = DecodeOptions { height_scale_m: 1000.0, ..opts(Encoding::Gray) };
    let hf = decode(Path::new("a.png"), &png_bytes(&img), &o).unwrap().heightfield;
    assert_eq!(hf.heights, vec![0.0, 1000.0, 1000.0, 0.0]);
}

#[test]
fn gray_stored_as_rgb_is_gray() {
    let img = ImageBuffer::from_fn(4, 4, |i, j| Rgb([(i * 60 + j) as u8; 3]));
    let d = decode(Path::new("g.png"), &png_bytes(&img), &opts(Encoding::Auto)).unwrap();
    assert_eq!(d.encoding, Encoding::Gray);
    assert_eq!(d.heightfield.at(3, 2), (182.0 / 255.0 * 100.0) as f32);
}

#[test]
fn auto_refuses_colour_rgb_and_names_the_choices() {
    let img = ImageBuffer::from_fn(4, 4, |i, _| Rgb([1, 2, i as u8]));
    let e = err_text(decode(Path::new("c.png"), &png_bytes(&img), &opts(Encoding::Auto)).unwrap_err());
    for word in ["c.png", "terrain-rgb", "terrarium", "gray", "column 0, row 0"] {
        assert!(e.contains(word), "{word:?} missing from: {e}");
    }
}

#[test]
fn terrain_rgb_formula() {
    let img = ImageBuffer::from_fn(2, 1, |i, _| if i == 0 { Rgba([1u8, 134, 160, 255]) } else { Rgba([0, 0, 0, 255]) });
    let hf = decode(Path::new("t.png"), &png_bytes(&img), &opts(Encoding::TerrainRgb)).unwrap().heightfield;
    assert_eq!(hf.at(0, 0), ((65536.0 + 134.0 * 256.0 + 160.0) * 0.1 - 10000.0) as f32);
    assert_eq!(hf.at(1, 0), -10000.0);
}

#[test]
fn terrarium_formula() {
    let img = ImageBuffer::from_fn(1, 2, |_, j| if j == 0 { Rgb([128u8, 10, 128]) } else { Rgb([127, 255, 0]) });
    let hf = decode(Path::new("t.png"), &png_bytes(&img), &opts(Encoding::Terrarium)).unwrap().heightfield;
    assert_eq!(hf.at(0, 0), 10.5);
    assert_eq!(hf.at(0, 1), -1.0);
}

#[test]
fn colour_encodings_refuse_gray_images() {
    let img = ImageBuffer::from_fn(2, 2, |_, _| Luma([3u8]));
    let e = err_text(decode(Path::new("g.png"), &png_bytes(&img), &opts(Encoding::TerrainRgb)).unwrap_err());
    assert!(e.contains("grayscale") && e.contains("--encoding gray"), "{e}");
}

fn hgt_bytes(side: usize, f: impl Fn(usize, usize) -> i16) -> Vec<u8> {
    let mut out = Vec::with_capacity(side * side * 2);
    for j in 0..side {
        for i in 0..side {
            out.extend_from_slice(&f(i, j).to_be_bytes());
        }
    }
    out
}

#[test]
fn hgt_fills_voids_from_neighbours_and_counts_them() {
    let side = 1201;
    let bytes = hgt_bytes(side, |i, j| {
        if (500..503).contains(&i) && (600..602).contains(&j) || (i, j) == (0, 0) {
            -32768
        } else {
            250
        }
    });
    let d = decode(Path::new("N00E000.hgt"), &bytes, &opts(Encoding::Auto)).unwrap();
    assert_eq!(d.encoding, Encoding::Hgt);
    assert_eq!(d.voids_filled, 7);
    assert_eq!((d.heightfield.width, d.heightfield.height), (1201, 1201));
    assert!(d.heightfield.heights.iter().all(|&h| h == 250.0), "voids take their neighbours' height");
}

#[test]
fn hgt_void_fill_interpolates_between_different_neighbours() {
    // a 3×3 with the middle row void: fill from above (0) and below (90)
    let bytes = hgt_bytes(3, |_, j| match j {
        0 => 0,
        1 => -32768,
        _ => 90,
    });
    let d = decode(Path::new("x.hgt"), &bytes, &opts(Encoding::Hgt)).unwrap();
    assert_eq!(d.voids_filled, 3);
    assert_eq!(d.heightfield.at(1, 1), 45.0);
}

#[test]
fn hgt_all_void_and_bad_sizes_are_errors() {
    let e = err_text(decode(Path::new("v.hgt"), &hgt_bytes(3, |_, _| -32768), &opts(Encoding::Hgt)).unwrap_err());
    assert!(e.contains("v.hgt") && e.contains("void"), "{e}");
    let e = err_text(decode(Path::new("v.hgt"), &[0u8; 10], &opts(Encoding::Hgt)).unwrap_err());
    assert!(e.contains("not a square"), "{e}");
    let e = err_text(decode(Path::new("v.hgt"), &[0u8; 9], &opts(Encoding::Hgt)).unwrap_err());
    assert!(e.contains("odd"), "{e}");
}

#[test]
fn r16_needs_matching_size() {
    let mut bytes = Vec::new();
    for v in [0u16, 65535, 32768, 1, 2, 3] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let o = DecodeOptions { size: Some((3, 2)), height_scale_m: 65535.0, ..opts(Encoding::Auto) };
    let d = decode(Path::new("m.r16"), &bytes, &o).unwrap();
    assert_eq!(d.encoding, Encoding::R16);
    assert_eq!(d.heightfield.heights, vec![0.0, 65535.0, 32768.0, 1.0, 2.0, 3.0]);
    let o = DecodeOptions { size: Some((4, 2)), ..o };
    let e = err_text(decode(Path::new("m.raw"), &bytes, &o).unwrap_err());
    assert!(e.contains("m.raw") && e.contains("--size 4x2") && e.contains("16 bytes"), "{e}");
    let e = err_text(decode(Path::new("m.raw"), &bytes, &opts(Encoding::Auto)).unwrap_err());
    assert!(e.contains("--size"), "{e}");
}

#[test]
fn float_tiff_in_metres() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dem.tif");
    let data: Vec<f32> = (0..12).map(|k| k as f32 * 1.25 - 3.0).collect();
    {
        let file = std::fs::File::create(&path).unwrap();
        let mut enc = tiff::encoder::TiffEncoder::new(file).unwrap();
        enc.write_image::<tiff::encoder::colortype::Gray32Float>(4, 3, &data).unwrap();
    }
    let d = load(&path, &opts(Encoding::Auto)).unwrap();
    assert_eq!(d.encoding, Encoding::Float);
    assert_eq!(d.heightfield.heights, data);
    assert_eq!((d.heightfield.width, d.heightfield.height), (4, 3));
}

#[test]
fn gray16_tiff() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dem16.tiff");
    let img = ImageBuffer::from_fn(3, 3, |i, j| Luma([(i * 1000 + j) as u16]));
    img.save(&path).unwrap();
    let d = load(&path, &DecodeOptions { height_scale_m: 65535.0, ..opts(Encoding::Auto) }).unwrap();
    assert_eq!(d.encoding, Encoding::Gray);
    assert_eq!(d.heightfield.at(2, 1), 2001.0);
}

#[test]
fn bad_files_name_the_file_and_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty.png");
    std::fs::write(&empty, b"").unwrap();
    let text = dir.path().join("notes.png");
    std::fs::write(&text, b"this is not an image\n").unwrap();
    let img = ImageBuffer::from_fn(64, 64, |i, j| Luma([(i ^ j) as u8]));
    let full = png_bytes(&img);
    let truncated = dir.path().join("cut.png");
    std::fs::write(&truncated, &full[..full.len() / 2]).unwrap();
    let missing = dir.path().join("missing.png");
    for (path, word) in
        [(&empty, "empty"), (&text, "not a recognised image"), (&truncated, "decode"), (&missing, "cannot read")]
    {
        let e = err_text(load(path, &opts(Encoding::Auto)).unwrap_err());
        assert!(e.contains(path.file_name().unwrap().to_str().unwrap()), "file not named: {e}");
        assert!(e.contains(word), "{word:?} missing: {e}");
    }
}

#[test]
fn size_limit_is_checked_before_decoding() {
    let img = ImageBuffer::from_fn(100, 50, |_, _| Luma([0u8]));
    let o = DecodeOptions { max_samples: 4999, ..opts(Encoding::Auto) };
    let e = err_text(decode(Path::new("big.png"), &png_bytes(&img), &o).unwrap_err());
    assert!(e.contains("100×50") && e.contains("--max-samples"), "{e}");
    let o = DecodeOptions { max_samples: 8, size: Some((3, 3)), ..opts(Encoding::R16) };
    assert!(matches!(decode(Path::new("b.r16"), &[0u8; 18], &o), Err(HeightfieldError::TooLarge { .. })));
    // a huge declared size fails on the limit, not by allocating
    let o = DecodeOptions { size: Some((1 << 30, 1 << 30)), ..opts(Encoding::R16) };
    assert!(matches!(decode(Path::new("b.r16"), &[0u8; 18], &o), Err(HeightfieldError::TooLarge { .. })));
}

#[test]
fn invalid_cell_size_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.png");
    std::fs::write(&p, png_bytes(&ImageBuffer::from_fn(2, 2, |_, _| Luma([0u8])))).unwrap();
    for cell in [0.0, -1.0, f64::NAN] {
        let e = err_text(load(&p, &DecodeOptions { cell_size_m: cell, ..opts(Encoding::Auto) }).unwrap_err());
        assert!(e.contains("--cell-size"), "{e}");
    }
}

proptest! {
    /// Arbitrary bytes under any encoding and name never panic: they decode or give an error.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600), enc in 0usize..7, ext in 0usize..5) {
        let encs = [Encoding::Auto, Encoding::Gray, Encoding::TerrainRgb, Encoding::Terrarium, Encoding::Hgt, Encoding::R16, Encoding::Float];
        let name = ["x.png", "x.tif", "x.hgt", "x.r16", "x"][ext];
        let o = DecodeOptions { encoding: encs[enc], max_samples: 1 << 16, ..DecodeOptions::default() };
        if let Ok(d) = decode(Path::new(name), &bytes, &o) {
            prop_assert_eq!(d.heightfield.heights.len(), d.heightfield.width * d.heightfield.height);
            prop_assert!(d.heightfield.heights.iter().all(|h| h.is_finite()));
        }
    }

    /// Corrupting a valid PNG anywhere never panics.
    #[test]
    fn corrupted_png_never_panics(pos in 0usize..400, val in any::<u8>(), cut in 0usize..400) {
        let img = ImageBuffer::from_fn(9, 7, |i, j| Luma([(i * 7 + j) as u16]));
        let mut bytes = png_bytes(&img);
        let n = bytes.len();
        bytes[pos % n] = val;
        bytes.truncate(n - cut % n);
        let _ = decode(Path::new("c.png"), &bytes, &DecodeOptions::default());
    }
}

fn shared(name: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/heightmaps").join(name);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipping: {} is absent (../shared/data not beside the project)", p.display());
        None
    }
}

#[test]
fn shared_fuji_terrain_rgb() {
    let Some(p) = shared("martini_fuji.png") else { return };
    let d = load(&p, &opts(Encoding::TerrainRgb)).unwrap();
    let (lo, hi) = d.heightfield.height_range().unwrap();
    assert_eq!((d.heightfield.width, d.heightfield.height), (512, 512));
    assert!((lo - 13.7).abs() < 0.05 && (hi - 3751.0).abs() < 0.05, "{lo}..{hi}");
    // auto refuses it: its channels differ
    assert!(load(&p, &opts(Encoding::Auto)).unwrap_err().to_string().contains("terrain-rgb"));
}

#[test]
fn shared_srtm_hgt_voids() {
    let Some(p) = shared("hades32_N44E033.hgt") else { return };
    let d = load(&p, &opts(Encoding::Auto)).unwrap();
    assert_eq!(d.voids_filled, 852);
    let (lo, hi) = d.heightfield.height_range().unwrap();
    assert!(lo >= -18.0 && hi <= 1181.0, "{lo}..{hi}");
}

#[test]
fn shared_puget_sound_16bit() {
    let Some(p) = shared("diligent_ps_height_1k.png") else { return };
    let d = load(&p, &DecodeOptions { height_scale_m: 6553.5, cell_size_m: 160.0, ..opts(Encoding::Auto) }).unwrap();
    let (lo, hi) = d.heightfield.height_range().unwrap();
    assert_eq!((d.heightfield.width, d.encoding), (1025, Encoding::Gray));
    assert!(lo == 0.0 && (hi - 4379.8).abs() < 0.01, "{lo}..{hi}");
}

#[test]
fn shared_gazebo_maps() {
    let Some(p) = shared("gzcommon_heightmap_flat_513x513.png") else { return };
    let d = load(&p, &opts(Encoding::Auto)).unwrap();
    assert_eq!(d.heightfield.height_range(), Some((0.0, 0.0)));
    for name in ["gzcommon_grayscale_16bit.png", "gzcommon_grayscale_8bit.png"] {
        let d = load(&shared(name).unwrap(), &opts(Encoding::Auto)).unwrap();
        assert_eq!((d.heightfield.width, d.heightfield.height, d.encoding), (4, 4, Encoding::Gray));
    }
    // the bowl is stored as RGB; whether auto accepts it depends on its channels being equal
    let bowl = shared("gzcommon_heightmap_bowl.png").unwrap();
    match load(&bowl, &opts(Encoding::Auto)) {
        Ok(d) => assert_eq!(d.encoding, Encoding::Gray),
        Err(e) => assert!(e.to_string().contains("--encoding gray"), "{e}"),
    }
    assert_eq!(load(&bowl, &opts(Encoding::Gray)).unwrap().heightfield.width, 129);
}

/// A TIFF (decoded whole, its samples moved out of the image) reads as the same image saved as a
/// PNG (decoded a row at a time): every 8/16-bit gray and RGB pixel type, with and without alpha,
/// gray stored as RGB or not, every encoding; the same heights and exact references, or the same
/// error.
#[test]
fn tiff_and_png_of_one_image_decode_alike() {
    use image::DynamicImage as D;
    let (w, h) = (11u32, 6u32);
    let v = |i: u32, j: u32, c: u32| ((i * 37 + j * 101 + c * 53) * 2654435761u32 >> 7) as u16;
    let mut decoded = 0;
    for equal in [true, false] {
        let c = |k: u32| if equal { 0 } else { k };
        let images = [
            D::ImageLuma8(ImageBuffer::from_fn(w, h, |i, j| Luma([v(i, j, 0) as u8]))),
            D::ImageLumaA8(ImageBuffer::from_fn(w, h, |i, j| image::LumaA([v(i, j, 0) as u8, 200]))),
            D::ImageLuma16(ImageBuffer::from_fn(w, h, |i, j| Luma([v(i, j, 0)]))),
            D::ImageLumaA16(ImageBuffer::from_fn(w, h, |i, j| image::LumaA([v(i, j, 0), 9000]))),
            D::ImageRgb8(ImageBuffer::from_fn(w, h, |i, j| Rgb([0, 1, 2].map(|k| v(i, j, c(k)) as u8)))),
            D::ImageRgba8(ImageBuffer::from_fn(w, h, |i, j| {
                let p = [0, 1, 2].map(|k| v(i, j, c(k)) as u8);
                Rgba([p[0], p[1], p[2], 255])
            })),
            D::ImageRgb16(ImageBuffer::from_fn(w, h, |i, j| Rgb([0, 1, 2].map(|k| v(i, j, c(k)))))),
            D::ImageRgba16(ImageBuffer::from_fn(w, h, |i, j| {
                let p = [0, 1, 2].map(|k| v(i, j, c(k)));
                Rgba([p[0], p[1], p[2], 65535])
            })),
        ];
        for img in images {
            let encode = |format| {
                let mut out = std::io::Cursor::new(Vec::new());
                img.write_to(&mut out, format).ok().map(|_| out.into_inner())
            };
            let (Some(tiff), Some(png)) = (encode(image::ImageFormat::Tiff), encode(image::ImageFormat::Png)) else {
                continue; // (a pixel type one of the encoders does not write)
            };
            for encoding in [Encoding::Auto, Encoding::Gray, Encoding::TerrainRgb, Encoding::Terrarium] {
                let o = DecodeOptions { height_scale_m: 812.5, height_offset_m: -3.25, ..opts(encoding) };
                let what = format!("{:?} equal={equal} {encoding:?}", img.color());
                match (decode(Path::new("map"), &tiff, &o), decode(Path::new("map"), &png, &o)) {
                    (Ok(a), Ok(b)) => {
                        let (x, y) = (&a.heightfield, &b.heightfield);
                        assert_eq!(a.encoding, b.encoding, "{what}");
                        assert_eq!(x.heights, y.heights, "{what}");
                        for k in 0..x.heights.len() {
                            assert_eq!(x.reference(k).to_bits(), y.reference(k).to_bits(), "{what}");
                        }
                        decoded += 1;
                    }
                    (Err(a), Err(b)) => assert_eq!(err_text(a), err_text(b), "{what}"),
                    (a, b) => panic!("{what}: tiff {:?}, png {:?}", a.map(|d| d.encoding), b.map(|d| d.encoding)),
                }
            }
        }
    }
    assert!(decoded >= 16, "{decoded}");
}
