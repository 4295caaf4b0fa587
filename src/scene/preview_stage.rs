//! The preview stage: `map.png`, the terrain's shaded relief from above with the snow cover and
//! the placements drawn over it, and `preview.png`, scene.glb rendered from the first view.

use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::mesh::Scene;
use crate::plants::palette;
use crate::scene::cache::KeyBuilder;
use crate::scene::error::{SceneBuildError, StageError};
use crate::scene::pipeline::{read_back, Stage, StageJob, TerrainHandoff};
use crate::scene::preview::{footprint_m, PreviewLayer};
use crate::scene::view_stage::ViewStageReport;
use crate::scene::Preset;
use crate::snow::CoverMask;

fn fail(stage: Stage) -> impl Fn(String) -> StageError {
    move |message| StageError::Failed { stage: stage.name(), message }
}

/// Version of the preview stage's output for given inputs (see [`TERRAIN_ALGORITHM_VERSION`]).
/// 2: a tree species without an L-system is drawn at its built-in tree's height. 3: preview.png is
/// the first view's perspective render of scene.glb, the top-down drawing moved to map.png. 4: lit
/// through the materials' normal maps. 5: scene.glb's trees switch where the joint chain search
/// puts them (plants 11), 6: and with small views sampled more finely (plants 12). 7: the terrain
/// lit through its normal maps (terrain 6). 8: its snow layer from the scene's snow cover (terrain 7).
/// 9: its soil layer where the species leave the ground bare (terrain 8). 10: impostors facing the
/// eye and trees' rebuilt LoD1 (view 11). 11: the terrain meshed in regions (terrain 9). 12: the
/// chunked terrain meshed in bands (terrain 10).
pub const PREVIEW_ALGORITHM_VERSION: u32 = 12;

/// What the preview stage produced.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct PreviewStageReport {
    pub file: PathBuf,
    pub width_px: u32,
    pub height_px: u32,
    /// The top-down map (`map.png`) when `preview.png` is the first view's perspective render.
    #[serde(default)]
    pub map: Option<PathBuf>,
    /// What the perspective render drew (scene.glb from the first view), when it is one.
    #[serde(default)]
    pub view: Option<PreviewViewFigures>,
    pub seconds: f64,
}

/// The perspective preview's figures.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct PreviewViewFigures {
    pub camera: String,
    pub triangles: u64,
    pub instances: u64,
}

pub const PREVIEW_SIZE_PX: u32 = 1024;

/// Draws preview.png: the terrain's shaded relief, the snow cover (when given) blended in white by
/// its weight, then the placements (colour, positions) over it.
pub fn run_preview(
    terrain: &Scene,
    placements: &[PreviewLayer],
    cover: Option<&CoverMask>,
    view: Option<(&Scene, &crate::scene::view::Camera)>,
    scene_dir: &Path,
) -> Result<PreviewStageReport, StageError> {
    let t0 = Instant::now();
    let f = fail(Stage::Preview);
    let mut canvas = crate::scene::preview::terrain_preview(terrain, PREVIEW_SIZE_PX);
    if let Some(v) = crate::scene::preview::preview_view(terrain, PREVIEW_SIZE_PX) {
        if let Some(mask) = cover {
            crate::scene::preview::draw_cover(&mut canvas, &v, mask);
        }
        crate::scene::preview::draw_placements(&mut canvas, &v, placements);
    }
    let file = PathBuf::from("preview.png");
    let Some((scene, camera)) = view else {
        crate::scene::preview::write_png(&canvas, &scene_dir.join(&file)).map_err(|e| f(e.to_string()))?;
        return Ok(PreviewStageReport {
            file,
            width_px: canvas.width,
            height_px: canvas.height,
            map: None,
            view: None,
            seconds: t0.elapsed().as_secs_f64(),
        });
    };
    // the map keeps the top-down drawing; preview.png is the scene as the first view sees it
    let map = PathBuf::from("map.png");
    crate::scene::preview::write_png(&canvas, &scene_dir.join(&map)).map_err(|e| f(e.to_string()))?;
    let scale = (PREVIEW_VIEW_WIDTH_PX as f64 / camera.size_px[0] as f64).min(1.0);
    let (w, h) = (
        (camera.size_px[0] as f64 * scale).round().max(16.0) as u32,
        (camera.size_px[1] as f64 * scale).round().max(16.0) as u32,
    );
    let (render, figures) =
        crate::scene::view_render::render_view(scene, camera, w, h).map_err(|e| f(format!("scene.glb: {e}")))?;
    crate::scene::preview::write_png(&render, &scene_dir.join(&file)).map_err(|e| f(e.to_string()))?;
    Ok(PreviewStageReport {
        file,
        width_px: w,
        height_px: h,
        map: Some(map),
        view: Some(PreviewViewFigures {
            camera: camera.name.clone(),
            triangles: figures.triangles,
            instances: figures.instances,
        }),
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Width of the perspective preview (the view's aspect kept; smaller views at their own size).
pub const PREVIEW_VIEW_WIDTH_PX: u32 = 1280;

/// Where the preview's placements come from.
pub enum PreviewPlacements<'a> {
    /// No scatter stage ran.
    None,
    /// The scatter stage's fresh output (positions as stored: f32).
    Fresh(&'a [PreviewLayer]),
    /// A cached scatter stage's tables (species name, CSV), read only if the preview runs.
    Tables(&'a [(String, PathBuf)]),
}

/// The stage in a scene build.
pub struct PreviewJob<'a> {
    pub preset: &'a Preset,
    pub terrain: &'a TerrainHandoff,
    /// The placements and the scatter stage's key.
    pub placements: (PreviewPlacements<'a>, Option<&'a str>),
    /// The snow cover and the snow stage's key.
    pub cover: Option<(&'a CoverMask, &'a str)>,
    /// The view stage's report and key (preview.png then renders scene.glb from the first view).
    pub view: Option<(&'a ViewStageReport, &'a str)>,
}

impl StageJob for PreviewJob<'_> {
    type Report = PreviewStageReport;
    type Artifact = ();
    const STAGE: Stage = Stage::Preview;

    fn key(&self) -> Result<String, SceneBuildError> {
        let mut k = KeyBuilder::new("preview", PREVIEW_ALGORITHM_VERSION);
        k.add(self.terrain.key.as_bytes()).add(&PREVIEW_SIZE_PX.to_le_bytes());
        if let Some(scatter_key) = self.placements.1 {
            k.add(scatter_key.as_bytes());
        }
        if let Some((_, snow_key)) = self.cover {
            k.add(b"snow").add(snow_key.as_bytes());
        }
        if let Some((_, view_key)) = self.view {
            k.add(b"view").add(view_key.as_bytes());
        }
        Ok(k.finish())
    }

    fn files(report: &PreviewStageReport) -> Vec<PathBuf> {
        std::iter::once(report.file.clone()).chain(report.map.clone()).collect()
    }

    fn run(&self, dir: &Path) -> Result<(PreviewStageReport, ()), SceneBuildError> {
        // fresh placements are drawn where they are (they can be millions of points)
        let layers: Cow<[PreviewLayer]> = match &self.placements.0 {
            PreviewPlacements::None => Cow::Owned(Vec::new()),
            PreviewPlacements::Fresh(layers) => Cow::Borrowed(layers),
            PreviewPlacements::Tables(tables) => Cow::Owned(placements_from_tables(dir, tables, self.preset)?),
        };
        // the perspective preview draws scene.glb as written (cached or not, the same bytes)
        let view = match self.view.and_then(|(report, _)| report.views.first().map(|v| (report, v))) {
            Some((report, v)) => Some((read_back(dir, &report.scene_file)?, v.camera.clone())),
            None => None,
        };
        let view = view.as_ref().map(|(s, c)| (s, c));
        let cover = self.cover.map(|(m, _)| m);
        Ok((run_preview(self.terrain.scene()?, &layers, cover, view, dir)?, ()))
    }
}

/// Positions of every species' placements as scene.glb stores them (f32), read from the tables.
fn placements_from_tables(
    dir: &Path,
    tables: &[(String, PathBuf)],
    preset: &Preset,
) -> Result<Vec<PreviewLayer>, SceneBuildError> {
    preset
        .species
        .iter()
        .enumerate()
        .map(|(index, s)| {
            let mut points = Vec::new();
            if let Some((_, rel)) = tables.iter().find(|(n, _)| *n == s.rules.name) {
                let path = dir.join(rel);
                let rows = crate::export::table::read_placements(&path)
                    .map_err(|message| SceneBuildError::Io { path: path.clone(), message })?;
                points.extend(rows.iter().map(|r| r.position.map(|v| v as f32 as f64)));
            }
            Ok(PreviewLayer {
                color: palette::species_color(s.kind, index),
                kind: s.kind,
                footprint_m: footprint_m(s),
                positions: points,
            })
        })
        .collect()
}
