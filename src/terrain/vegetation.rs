//! What grows on the terrain, texel by texel: the input of the soil layer and of the surface
//! attributes every terrain vertex carries (the terrain walk-through thesis' per-polygon TEXTURE,
//! TYPE, DENSITY and SIZE, as `_SURFACE`).
//!
//! Plain data: a scene build fills it from its species' placement rules (the density each species'
//! rules leave at every texel, the same the scatter stage writes as `placements/density_<k>.png`),
//! and the material layers read it. A terrain built alone has none.

/// The ground a species grows on, for the material layers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ground {
    /// Grass and flowers: where they grow, the gentle ground is the grass layer.
    Grass,
    /// Trees and meshes: the ground under them is soil (forest floor).
    Canopy,
}

/// One species' density over the terrain.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeciesCover {
    pub ground: Ground,
    /// Instances per m² where its weight is 1.
    pub max_density: f64,
    /// Height of one plant in metres (the middle of its scale range applied).
    pub height_m: f64,
    /// Ground one plant covers seen from above, m².
    pub footprint_m2: f64,
    /// Density over `max_density` at each texel centre, row-major, `size[0]` wide, of the
    /// cover's texel rows ([`VegetationCover::first_row`] on; every row of a whole cover); texel
    /// (x, y) at ((x + ½)/w, (y + ½)/h) of the extent, row 0 at its minimum z.
    pub weights: Vec<f32>,
}

/// Every species' density on one texel grid over the terrain.
#[derive(Debug, Clone, PartialEq)]
pub struct VegetationCover {
    /// [x0, z0, x1, z1] in metres.
    pub extent: [f64; 4],
    /// Texels (width, height).
    pub size: [u32; 2],
    /// In preset order (`_SURFACE`'s TYPE is the 1-based index in this list).
    pub species: Vec<SpeciesCover>,
    /// The first texel row the species' weights hold: 0 for a whole cover; a band of a terrain
    /// meshed in bands holds its own rows ([`crate::scene::ground_cover::cover_rows`]), which
    /// answer [`VegetationCover::soil_share_texel`] alone. Only a whole cover answers points
    /// ([`VegetationCover::at`]: a point reads the texels around it).
    pub first_row: usize,
}

/// The vegetation at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoverAt {
    /// Grass and flower density over their max, summed and clamped to 1.
    pub grass: f64,
    /// Tree and mesh density over their max, summed and clamped to 1.
    pub canopy: f64,
    /// 1-based index of the species covering the most ground here (density × footprint); 0 where
    /// nothing grows.
    pub dominant: usize,
    /// That species' instances per m² here (0 where nothing grows).
    pub density: f64,
    /// Its plant height in metres (0 where nothing grows).
    pub height_m: f64,
}

impl VegetationCover {
    /// Whether any species is grass or flowers (then the soil layer is the ground they leave bare).
    pub fn has_grass(&self) -> bool {
        self.species.iter().any(|s| s.ground == Ground::Grass)
    }

    /// The texel rows the cover holds.
    pub fn rows(&self) -> std::ops::Range<usize> {
        let w = (self.size[0] as usize).max(1);
        let held = self.species.first().map_or(0, |s| s.weights.len() / w);
        self.first_row..self.first_row + held
    }

    /// The texel rows `rows` of this cover (`None` when it does not hold them all).
    pub fn take_rows(&self, rows: std::ops::Range<usize>) -> Option<VegetationCover> {
        let held = self.rows();
        if rows.start < held.start || rows.end > held.end || rows.start > rows.end {
            return None;
        }
        let w = self.size[0] as usize;
        let at = (rows.start - held.start) * w..(rows.end - held.start) * w;
        let species = self
            .species
            .iter()
            .map(|s| SpeciesCover { weights: s.weights[at.clone()].to_vec(), ..s.clone() })
            .collect();
        Some(VegetationCover { species, first_row: rows.start, ..self.clone_empty() })
    }

    /// Consecutive rows of one cover, put together in order (`None` when they are not: another
    /// grid, extent or species, or a row missing or twice).
    pub fn stack(parts: &[VegetationCover]) -> Option<VegetationCover> {
        let first = parts.first()?;
        let mut out = VegetationCover { first_row: first.first_row, ..first.clone_empty() };
        let mut next = first.first_row;
        for p in parts {
            let fits = p.extent == out.extent && p.size == out.size && p.species.len() == out.species.len();
            let figures_fit = p.species.iter().zip(&out.species).all(|(a, b)| {
                (a.ground, a.max_density, a.height_m, a.footprint_m2)
                    == (b.ground, b.max_density, b.height_m, b.footprint_m2)
            });
            if !fits || !figures_fit || p.first_row != next {
                return None;
            }
            for (o, s) in out.species.iter_mut().zip(&p.species) {
                o.weights.extend_from_slice(&s.weights);
            }
            next = p.rows().end;
        }
        Some(out)
    }

    /// This cover's grid and species without their weights.
    fn clone_empty(&self) -> VegetationCover {
        VegetationCover {
            extent: self.extent,
            size: self.size,
            species: self.species.iter().map(|s| SpeciesCover { weights: Vec::new(), ..s.clone() }).collect(),
            first_row: self.first_row,
        }
    }

    /// Where world (x, z) falls between texel centres: the texel columns and rows around it and
    /// the fractions between them (clamped at the borders).
    fn texel_cell(&self, x: f64, z: f64) -> ([usize; 2], [usize; 2], [f64; 2]) {
        let [w, h] = self.size.map(|v| (v as usize).max(1));
        let [x0, z0, x1, z1] = self.extent;
        let fx = ((x - x0) / (x1 - x0) * w as f64 - 0.5).clamp(0.0, (w - 1) as f64);
        let fz = ((z - z0) / (z1 - z0) * h as f64 - 0.5).clamp(0.0, (h - 1) as f64);
        let (fx, fz) = (if fx.is_finite() { fx } else { 0.0 }, if fz.is_finite() { fz } else { 0.0 });
        let (i, j) = (fx.floor() as usize, fz.floor() as usize);
        ([i, (i + 1).min(w - 1)], [j, (j + 1).min(h - 1)], [fx - i as f64, fz - j as f64])
    }

    /// Whether the cover holds the texel rows [`VegetationCover::at`] reads at world (x, z) (a
    /// whole cover always does; a cover of some rows, those around its rows' centres).
    pub fn holds_point(&self, x: f64, z: f64) -> bool {
        let (_, [j, j1], _) = self.texel_cell(x, z);
        let rows = self.rows();
        rows.contains(&j) && rows.contains(&j1)
    }

    /// A species' weight at world (x, z): bilinear between texel centres, clamped at the borders
    /// (0 where the cover does not hold the rows around it: see [`VegetationCover::holds_point`]).
    fn weight(&self, s: &SpeciesCover, x: f64, z: f64) -> f64 {
        let [w, h] = self.size.map(|v| v as usize);
        let rows = self.rows();
        if w == 0 || h == 0 || s.weights.len() != w * rows.len() || !self.holds_point(x, z) {
            return 0.0;
        }
        let ([i, i1], [j, j1], [a, b]) = self.texel_cell(x, z);
        let first = self.first_row;
        let v = |i: usize, j: usize| s.weights[(j - first) * w + i] as f64;
        let top = v(i, j) * (1.0 - a) + v(i1, j) * a;
        let bottom = v(i, j1) * (1.0 - a) + v(i1, j1) * a;
        (top * (1.0 - b) + bottom * b).clamp(0.0, 1.0)
    }

    /// The vegetation at world (x, z).
    pub fn at(&self, x: f64, z: f64) -> CoverAt {
        self.at_with(|s| self.weight(s, x, z))
    }

    /// The vegetation at texel (i, j)'s centre: its own weights (0 outside the rows held).
    pub fn at_texel(&self, i: usize, j: usize) -> CoverAt {
        let w = self.size[0] as usize;
        let at = j.checked_sub(self.first_row).filter(|_| i < w).map(|r| r * w + i);
        self.at_with(|s| at.and_then(|k| s.weights.get(k)).map_or(0.0, |&v| (v as f64).clamp(0.0, 1.0)))
    }

    /// The vegetation where each species' weight is `weight(species)`.
    fn at_with(&self, weight: impl Fn(&SpeciesCover) -> f64) -> CoverAt {
        let mut c = CoverAt { grass: 0.0, canopy: 0.0, dominant: 0, density: 0.0, height_m: 0.0 };
        let mut best = 0.0;
        for (k, s) in self.species.iter().enumerate() {
            let w = weight(s);
            match s.ground {
                Ground::Grass => c.grass += w,
                Ground::Canopy => c.canopy += w,
            }
            let density = w * s.max_density;
            let covered = density * s.footprint_m2;
            if covered > best {
                best = covered;
                c.dominant = k + 1;
                c.density = density;
                c.height_m = s.height_m;
            }
        }
        c.grass = c.grass.min(1.0);
        c.canopy = c.canopy.min(1.0);
        c
    }

    /// The share of the gentle ground (the grass layer without vegetation) that is soil at (x, z):
    /// in a scene with grass or flowers, the ground they leave bare (1 − their summed density
    /// weight); in a scene without, the forest floor under trees and meshes (their summed weight).
    pub fn soil_share(&self, x: f64, z: f64) -> f64 {
        self.soil_share_of(self.at(x, z))
    }

    /// [`VegetationCover::soil_share`] at texel (i, j)'s centre, from that texel's weights alone
    /// (what the layer maps' texel there is baked with).
    pub fn soil_share_texel(&self, i: usize, j: usize) -> f64 {
        self.soil_share_of(self.at_texel(i, j))
    }

    fn soil_share_of(&self, c: CoverAt) -> f64 {
        if self.has_grass() {
            1.0 - c.grass
        } else {
            c.canopy
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn species(ground: Ground, max_density: f64, footprint_m2: f64, weights: Vec<f32>) -> SpeciesCover {
        SpeciesCover { ground, max_density, height_m: 1.0 + max_density, footprint_m2, weights }
    }

    #[test]
    fn weights_are_exact_at_texel_centres_and_bilinear_between() {
        // 2 × 1 texels over [0, 4] × [0, 2]: centres at x = 1 and x = 3
        let cover = VegetationCover {
            extent: [0.0, 0.0, 4.0, 2.0],
            size: [2, 1],
            species: vec![species(Ground::Grass, 10.0, 0.05, vec![0.0, 1.0])],
            first_row: 0,
        };
        assert_eq!(cover.at(1.0, 1.0).grass, 0.0);
        // a texel reads its own weight; a cover of some rows answers its rows by texel alone
        assert_eq!((cover.at_texel(0, 0).grass, cover.at_texel(1, 0).grass), (0.0, 1.0));
        assert_eq!(cover.at_texel(2, 0).grass, 0.0, "outside the grid");
        let rows = VegetationCover { size: [2, 3], first_row: 2, ..cover.clone() };
        assert_eq!((rows.at_texel(1, 2).grass, rows.at_texel(1, 1).grass), (1.0, 0.0));
        // a point reads a cover of some rows where it holds the rows around it, else 0
        assert!(!rows.holds_point(3.0, 1.0));
        assert_eq!(rows.at(3.0, 1.0).grass, 0.0, "row 1 is not held");
        assert!(rows.holds_point(3.0, 2.0));
        assert_eq!(rows.at(3.0, 2.0).grass, 1.0, "row 2 (clamped) is");
        assert_eq!(rows.rows(), 2..3);
        assert_eq!(cover.at(3.0, 1.0).grass, 1.0);
        assert!((cover.at(2.0, 1.0).grass - 0.5).abs() < 1e-12);
        // clamped outside the centres
        assert_eq!(cover.at(0.0, 0.0).grass, 0.0);
        assert_eq!(cover.at(4.0, 2.0).grass, 1.0);
        assert_eq!(cover.soil_share(1.0, 1.0), 1.0);
        assert_eq!(cover.soil_share(3.0, 1.0), 0.0);
    }

    #[test]
    fn the_dominant_species_covers_the_most_ground_and_soil_follows_the_kinds() {
        let extent = [0.0, 0.0, 1.0, 1.0];
        // grass at full density covers 10 × 0.05 = 0.5; trees at 0.02 × 50 = 1.0 where full
        let grass = species(Ground::Grass, 10.0, 0.05, vec![1.0]);
        let trees = species(Ground::Canopy, 0.02, 50.0, vec![1.0]);
        let both = VegetationCover { extent, size: [1, 1], species: vec![grass.clone(), trees.clone()], first_row: 0 };
        let at = both.at(0.5, 0.5);
        assert_eq!((at.dominant, at.density, at.height_m), (2, 0.02, 1.02));
        assert_eq!((at.grass, at.canopy), (1.0, 1.0));
        assert_eq!(both.soil_share(0.5, 0.5), 0.0, "grass grows here: no soil");
        // a forest without grass: soil under the trees
        let forest = VegetationCover { extent, size: [1, 1], species: vec![trees.clone()], first_row: 0 };
        assert_eq!(forest.soil_share(0.5, 0.5), 1.0);
        // nothing grows: no type, no density
        let bare = VegetationCover {
            extent,
            size: [1, 1],
            species: vec![species(Ground::Canopy, 0.02, 50.0, vec![0.0])],
            first_row: 0,
        };
        let at = bare.at(0.5, 0.5);
        assert_eq!((at.dominant, at.density, at.height_m), (0, 0.0, 0.0));
        assert_eq!(bare.soil_share(0.5, 0.5), 0.0);
    }
}
