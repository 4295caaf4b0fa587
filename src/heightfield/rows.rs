//! Some rows of a map read in the map's coordinates: what a terrain band's unit shades its chunks
//! and bakes its texels from (docs/sharding.md). Sample (i, j) of [`MapRows`] is the map's (i, j),
//! held in `hf` at row j − `row0`; the normals and interpolations treat the map's border as the
//! border (never the window's), so they are the whole map's, bit for bit, wherever the rows they
//! read are held. [`Heightfield`]'s own normals are these of a window holding every row.

use super::Heightfield;

/// Rows `row0 .. row0 + hf.height` of a map of `map_height` rows.
#[derive(Debug, Clone, Copy)]
pub struct MapRows<'a> {
    pub hf: &'a Heightfield,
    pub row0: usize,
    pub map_height: usize,
}

impl<'a> MapRows<'a> {
    /// A whole map.
    pub fn whole(hf: &'a Heightfield) -> MapRows<'a> {
        MapRows { hf, row0: 0, map_height: hf.height }
    }

    /// `hf` as rows `row0 ..` of a map of `map_height` rows (`None` when they do not fit in it).
    pub fn new(hf: &'a Heightfield, row0: usize, map_height: usize) -> Option<MapRows<'a>> {
        (hf.height > 0 && row0 + hf.height <= map_height).then_some(MapRows { hf, row0, map_height })
    }

    /// The map's rows held: `row0 ..= last`.
    pub fn held(&self) -> std::ops::RangeInclusive<usize> {
        self.row0..=self.row0 + self.hf.height - 1
    }

    /// The rows [`MapRows::normal_at`] reads for sample row `j` (its neighbours, clamped to the map).
    pub fn normal_reach(&self, j: usize) -> std::ops::RangeInclusive<usize> {
        j.saturating_sub(1)..=(j + 1).min(self.map_height.saturating_sub(1))
    }

    /// The height of the map's sample (i, j). Panics when row j is not held.
    #[inline]
    pub fn at(&self, i: usize, j: usize) -> f32 {
        self.hf.at(i, j - self.row0)
    }

    /// The map's position of sample (i, j) (x = i·cell, z = j·cell).
    #[inline]
    pub fn position(&self, i: usize, j: usize) -> [f32; 3] {
        let cell = self.hf.cell_size_m;
        [(i as f64 * cell) as f32, self.at(i, j), (j as f64 * cell) as f32]
    }

    /// The map's UV0 of sample (i, j) ([`Heightfield::planar_uv`]).
    #[inline]
    pub fn planar_uv(&self, i: usize, j: usize) -> [f32; 2] {
        [(i as f64 / (self.hf.width - 1) as f64) as f32, (j as f64 / (self.map_height - 1) as f64) as f32]
    }

    /// [`Heightfield::normal_at`] of the map. Panics when a row it reads
    /// ([`MapRows::normal_reach`]) is not held.
    pub fn normal_at(&self, i: usize, j: usize) -> [f64; 3] {
        // (lo, hi) neighbours along one axis, clamped to the map: central inside, one-sided at edges
        let span = |k: usize, n: usize| (k.saturating_sub(1), (k + 1).min(n.saturating_sub(1)));
        let (i0, i1) = span(i, self.hf.width);
        let (j0, j1) = span(j, self.map_height);
        let slope = |a: f32, b: f32, steps: usize| {
            if steps == 0 {
                0.0
            } else {
                (b as f64 - a as f64) / (steps as f64 * self.hf.cell_size_m)
            }
        };
        let dhdx = slope(self.at(i0, j), self.at(i1, j), i1 - i0);
        let dhdz = slope(self.at(i, j0), self.at(i, j1), j1 - j0);
        let len = (dhdx * dhdx + 1.0 + dhdz * dhdz).sqrt();
        [-dhdx / len, 1.0 / len, -dhdz / len]
    }

    /// The four samples around continuous sample coordinates (s, t) (clamped to the map) and the
    /// fractions between them: ((i0, j0), (i1, j1), (fs, ft)).
    pub fn bilinear_cell(&self, s: f64, t: f64) -> ((usize, usize), (usize, usize), (f64, f64)) {
        let (w, h) = (self.hf.width, self.map_height);
        let (i0, j0) = (s.floor().max(0.0) as usize, t.floor().max(0.0) as usize);
        let (i0, j0) = (i0.min(w - 1), j0.min(h - 1));
        let (i1, j1) = ((i0 + 1).min(w - 1), (j0 + 1).min(h - 1));
        ((i0, j0), (i1, j1), ((s - i0 as f64).clamp(0.0, 1.0), (t - j0 as f64).clamp(0.0, 1.0)))
    }

    /// [`Heightfield::height_bilinear`] of the map: reads the sample rows around t.
    pub fn height_bilinear(&self, s: f64, t: f64) -> f64 {
        let ((i0, j0), (i1, j1), (fs, ft)) = self.bilinear_cell(s, t);
        let h = |i, j| self.at(i, j) as f64;
        let lerp = |a: f64, b: f64, f: f64| a + (b - a) * f;
        lerp(lerp(h(i0, j0), h(i1, j0), fs), lerp(h(i0, j1), h(i1, j1), fs), ft)
    }

    /// [`Heightfield::normal_bilinear`] of the map: reads the normals of the sample rows around t
    /// (and their neighbours).
    pub fn normal_bilinear(&self, s: f64, t: f64) -> [f64; 3] {
        let ((i0, j0), (i1, j1), (fs, ft)) = self.bilinear_cell(s, t);
        let (a, b, c, d) =
            (self.normal_at(i0, j0), self.normal_at(i1, j0), self.normal_at(i0, j1), self.normal_at(i1, j1));
        let n: [f64; 3] = std::array::from_fn(|k| {
            (a[k] * (1.0 - fs) + b[k] * fs) * (1.0 - ft) + (c[k] * (1.0 - fs) + d[k] * fs) * ft
        });
        crate::math::normalize3(n).unwrap_or([0.0, 1.0, 0.0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sample rows [`MapRows::normal_bilinear`] reads at row coordinate t.
    fn bilinear_reach(rows: &MapRows, t: f64) -> std::ops::RangeInclusive<usize> {
        let h = rows.map_height;
        let j0 = (t.floor().max(0.0) as usize).min(h - 1);
        let j1 = (j0 + 1).min(h - 1);
        *rows.normal_reach(j0).start()..=*rows.normal_reach(j1).end()
    }

    /// Rows of a map give the whole map's normals, interpolations and UVs bit for bit wherever
    /// what they read is held, the map's border rows included.
    #[test]
    fn rows_of_a_map_shade_as_the_whole_map() {
        let hf = crate::synth::ridged(41, 2.0, 90.0, 3);
        let whole = MapRows::whole(&hf);
        for (j0, j1) in [(0, 40), (0, 12), (9, 25), (30, 40), (40, 40)] {
            let window = hf.rows(j0, j1).unwrap();
            let rows = MapRows::new(&window, j0, hf.height).unwrap();
            for j in j0..=j1 {
                for i in 0..hf.width {
                    assert_eq!(rows.position(i, j), hf.position(i, j));
                    assert_eq!(rows.planar_uv(i, j), hf.planar_uv(i, j));
                    let reach = rows.normal_reach(j);
                    if rows.held().contains(reach.start()) && rows.held().contains(reach.end()) {
                        assert_eq!(rows.normal_at(i, j), hf.normal_at(i, j), "({i}, {j})");
                    }
                }
            }
            for k in 0..400 {
                let (s, t) = ((k * 37 % 401) as f64 * 0.1, j0 as f64 + (k % 97) as f64 * 0.137);
                let reach = bilinear_reach(&rows, t);
                if rows.held().contains(reach.start()) && rows.held().contains(reach.end()) {
                    assert_eq!(rows.normal_bilinear(s, t), hf.normal_bilinear(s, t), "({s}, {t})");
                    assert_eq!(whole.normal_bilinear(s, t), hf.normal_bilinear(s, t));
                }
            }
        }
        assert!(MapRows::new(&hf.rows(0, 10).unwrap(), 31, 41).is_none());
    }
}
