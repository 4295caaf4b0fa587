//! The `verdant` command line: parses arguments and calls the library. No pipeline logic here.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand, ValueEnum};
use verdant::export::quantize::Compact;
use verdant::failure::{Blame, Failure};
use verdant::heightfield::{DecodeOptions, Encoding, DEFAULT_MAX_SAMPLES};
use verdant::lsystem::expand::DEFAULT_MAX_SYMBOLS;
use verdant::lsystem::Dialect;
use verdant::plants::mesh_asset::{self, ObjOptions, UpAxis};
use verdant::plants::tree::{
    self as tree_job, TreeJob, TreeOptions, DEFAULT_MAX_SEGMENTS, DEFAULT_MAX_TRIANGLES, DEFAULT_RADIAL_SEGMENTS,
};
use verdant::plants::tree_lod::{self, MeshLodJob, TreeLodJob, TreeLodOptions};
use verdant::scene::build::{self as scene_build, BuildSettings, PresetSource};
use verdant::scene::pipeline::Stage;
use verdant::scene::preset;
use verdant::scene::shard::Shard;
use verdant::terrain::build::BuildOptions;
use verdant::terrain::job::{self, MeshMode, Source, TerrainJob};
use verdant::validate::{validate_file, ValidateOptions};

#[derive(Parser)]
#[command(
    name = "verdant",
    version,
    about = "Asset pipeline for games: heightmaps in, error-bounded terrain meshes out as glTF 2.0 / OBJ",
    long_about = "Asset pipeline for games and real-time scenes: heightmaps in, error-bounded terrain meshes out \
                  as glTF 2.0 (.glb, .gltf + .bin) or OBJ + MTL, with the measured error of every output.\n\n\
                  Conventions: metres, +Y up; heightmap column i, row j lies at x = i·cell, z = j·cell.\n\
                  Exit codes: 0 ok, 1 build or validation failure, 2 bad input or usage."
)]
struct Cli {
    /// Worker threads (default: all cores; at most 4 per core: more only adds switching). Outputs
    /// are identical for any thread count.
    #[arg(long, global = true, value_name = "N")]
    threads: Option<usize>,
    /// Print nothing but errors.
    #[arg(long, short, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Heightmap → terrain mesh within a vertical error bound, written as glTF or OBJ.
    ///
    /// Example: verdant terrain fuji.png --encoding terrain-rgb --cell-size 30 --max-error 5 -o out/fuji.glb --report out/fuji.json
    #[command(allow_negative_numbers = true)]
    Terrain(TerrainArgs),
    /// Re-import .glb/.gltf/.obj files and check them: indices in range, finite values, no
    /// degenerate triangles, unit normals, bounds equal to accessor min/max.
    ///
    /// Example: verdant validate out/fuji.glb --up-facing
    Validate(ValidateArgs),
    /// Build scenes from preset files into out/<scene>/ (meshes, manifest.json, report.json/.md,
    /// preview.png). With no preset, builds the embedded demo scene.
    ///
    /// Example: verdant build presets/*.toml --jobs 2
    Build(BuildArgs),
    /// Join the shard folders of `verdant build --shard I/N` into the scenes a single build makes
    /// (byte for byte): checks that all N shards of each preset are there and built from the same
    /// inputs, brings their cache entries in, and builds the rest (snow, placements, scene.glb,
    /// preview, manifest and report) into --out.
    ///
    /// Example: verdant merge presets/alpine.toml --shards shards/0 shards/1 --out out
    Merge(MergeArgs),
    /// Check a preset without building, or write a commented template.
    #[command(subcommand)]
    Preset(PresetCommand),
    /// Manage the stage cache of an output folder (<DIR>/.cache/).
    ///
    /// Example: verdant cache prune --out out
    #[command(subcommand)]
    Cache(CacheCommand),
    /// L-system file → tree mesh (branches, leaves, polygons) as glTF or OBJ, with a JSON report.
    ///
    /// Reads the three .ls dialects (the thesis' stochastic format, lparser 4 and 5; see
    /// docs/lsystems.md). The expansion streams into the mesh, so long expansions need no memory.
    ///
    /// A built-in tree instead of a file: `builtin:conifer`, `builtin:broadleaf`, `builtin:birch`,
    /// `builtin:bush` (grown to the species' height unless --height says otherwise).
    ///
    /// Example: verdant tree trees3.ls -o out/trees3.glb --report out/trees3.json
    Tree(TreeArgs),
    /// OBJ model (+ MTL and PNG/JPEG textures) → the LoD chain trees get: LoD0 the model, LoD1
    /// simplified, LoD2 decimated, LoD3 crossed billboards, LoD4 an impostor, with atlases.
    ///
    /// The model is turned to +Y up (--up-axis z for Z-up exports), scaled by --scale, and
    /// recentred: its lowest point at y = 0, the centre of its x/z footprint at the origin.
    ///
    /// Example: verdant mesh rock.obj -o out/rock.glb --scale 0.01 --up-axis z --report out/rock.json
    Mesh(MeshArgs),
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum UpAxisArg {
    /// +Y up (glTF, Maya, Blender's default OBJ export).
    Y,
    /// +Z up (3ds Max, CAD, photogrammetry).
    Z,
}

#[derive(Args)]
struct MeshArgs {
    /// Wavefront OBJ file; its `mtllib` and `map_Kd` files are read relative to it and to the MTL.
    #[arg(value_name = "FILE.obj")]
    input: PathBuf,
    /// Output .glb holding the MSFT_lod chain, with <stem>_LOD<n>.glb and <stem>_atlas.png
    /// (+ mips) beside it. Default: out/<input name>.glb.
    #[arg(short, long, value_name = "FILE.glb")]
    output: Option<PathBuf>,
    /// Levels of detail (1 to 5).
    #[arg(long, value_name = "N", default_value_t = tree_lod::TREE_LODS)]
    lods: usize,
    /// Side of the square atlas the billboards and impostor views are baked into.
    #[arg(long, value_name = "PX", default_value_t = tree_lod::DEFAULT_ATLAS_PX)]
    atlas_size: u32,
    /// Metres per file unit (0.01 for a model in centimetres).
    #[arg(long, value_name = "S", default_value_t = 1.0)]
    scale: f64,
    /// Which axis of the file points up.
    #[arg(long, value_enum, default_value_t = UpAxisArg::Y)]
    up_axis: UpAxisArg,
    /// Refuse models with more vertices than this.
    #[arg(long, value_name = "N", default_value_t = mesh_asset::DEFAULT_MAX_VERTICES)]
    max_vertices: usize,
    /// Refuse models with more triangles than this.
    #[arg(long, value_name = "N", default_value_t = mesh_asset::DEFAULT_MAX_TRIANGLES)]
    max_triangles: usize,
    /// Write a JSON report: what was loaded, and per LoD triangles, bytes, geometric and image
    /// error, switch distance (the speed/error table).
    #[arg(long, value_name = "FILE.json")]
    report: Option<PathBuf>,
    /// Skip the image analyzer (no switch distances: MSFT_lod coverages are 0); for timing.
    #[arg(long)]
    no_analysis: bool,
    /// How thoroughly the analyzer measures: `fast` (24 views up to 96 px, switches within 9 %;
    /// 12 views for a chain drawing over 6 M triangles a distance) or `exhaustive` (80 views up to
    /// 256 px at 4×4 samples, within 2 %; tens of times the work), what the fast figures are
    /// checked against in scripts/bench_trees.sh.
    #[arg(long, value_enum, value_name = "DETAIL", default_value_t = AnalysisArg::Fast)]
    analysis: AnalysisArg,
    /// glb/gltf: store vertex data compactly (KHR_mesh_quantization): positions as 16-bit
    /// integers on a grid per mesh (its largest side over 65,535; one grid for a LoD chain),
    /// normals and tangents 8-bit, texture coordinates 16-bit (outside 0..1 through the material's
    /// KHR_texture_transform), wind data as normalized bytes of their ranges (docs/wind.md). The
    /// quantization is folded into each level's reported error (`stored_error_m`).
    #[arg(long)]
    quantize: bool,
    /// glb/gltf: --quantize, then compress vertex, index and instance data with meshoptimizer's
    /// codecs (EXT_meshopt_compression: lossless; loaders need its decoder, which three.js and
    /// Babylon.js ship).
    #[arg(long)]
    compress: bool,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum AnalysisArg {
    Fast,
    Exhaustive,
}

impl AnalysisArg {
    fn detail(self) -> tree_lod::AnalysisDetail {
        match self {
            AnalysisArg::Fast => tree_lod::AnalysisDetail::Fast,
            AnalysisArg::Exhaustive => tree_lod::AnalysisDetail::Exhaustive,
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum DialectArg {
    /// Detect from the content.
    Auto,
    /// The point-sprite thesis' stochastic format (`3-2-2`, `X(100)=…`, `A(40)=…`).
    Ls,
    /// lparser 4 (positional lines, `X=…` rules, `@`).
    V4,
    /// lparser 5 (`recursion 12`, `rule X = …`).
    V5,
}

#[derive(Args)]
struct TreeArgs {
    /// L-system file (.ls), or `builtin:<name>` for a tree of the built-in library.
    #[arg(value_name = "FILE.ls")]
    input: PathBuf,
    /// Output file: .glb, .gltf (+ .bin) or .obj (+ .mtl). Default: out/<input name>.glb.
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,
    /// Seed of the stochastic rules and random turns; the same seed gives the same tree.
    #[arg(long, value_name = "N", default_value_t = 0)]
    seed: u64,
    /// File dialect.
    #[arg(long, value_enum, default_value_t = DialectArg::Auto)]
    dialect: DialectArg,
    /// Refuse trees drawing more segments than this.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_SEGMENTS)]
    max_segments: u64,
    /// Refuse trees needing more triangles than this.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_TRIANGLES)]
    max_triangles: u64,
    /// Refuse expansions longer than this many symbols.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_SYMBOLS)]
    max_symbols: u64,
    /// Vertices around each branch (3 to 64).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_RADIAL_SEGMENTS)]
    radial_segments: u32,
    /// Metres of one default step F (lparser 4's 100 units, lparser 5's and the thesis' 1 unit).
    #[arg(long, value_name = "METRES", default_value_t = 1.0)]
    step: f64,
    /// Scale the finished tree to this height in metres (default: the L-system's own scale, with a
    /// warning when that is under 5 cm or over 120 m; a built-in tree's species height).
    #[arg(long, value_name = "METRES")]
    height: Option<f64>,
    /// Write a JSON report: symbols, segments, triangles, branch levels, seconds, and per LoD
    /// triangles, bytes, geometric and image error, switch distance (the speed/error table).
    #[arg(long, value_name = "FILE.json")]
    report: Option<PathBuf>,
    /// Levels of detail (1 to 5): LoD0 full, LoD1 simplified, LoD2 leaf-cluster cards, LoD3
    /// crossed billboards, LoD4 one impostor. Above 1 the output must be .glb: it holds the
    /// MSFT_lod chain, with <stem>_LOD<n>.glb and the atlas <stem>_atlas.png (+ mips) beside it.
    /// Default: 5 for a .glb output, 1 (LoD0 only) for .gltf and .obj.
    #[arg(long, value_name = "N")]
    lods: Option<usize>,
    /// Trees grown from seeds derived from --seed, written as <stem>_v<k>… (1 to 64).
    #[arg(long, value_name = "K", default_value_t = 1)]
    variants: usize,
    /// Side of the square atlas the billboards, cards and impostor views are baked into.
    #[arg(long, value_name = "PX", default_value_t = tree_lod::DEFAULT_ATLAS_PX)]
    atlas_size: u32,
    /// Skip the image analyzer (no switch distances: MSFT_lod coverages are 0); for timing.
    #[arg(long)]
    no_analysis: bool,
    /// How thoroughly the analyzer measures: `fast` (24 views up to 96 px, switches within 9 %;
    /// 12 views for a chain drawing over 6 M triangles a distance) or `exhaustive` (80 views up to
    /// 256 px at 4×4 samples, within 2 %; tens of times the work), what the fast figures are
    /// checked against in scripts/bench_trees.sh.
    #[arg(long, value_enum, value_name = "DETAIL", default_value_t = AnalysisArg::Fast)]
    analysis: AnalysisArg,
    /// Leaves as glTF POINTS (one per leaf at its centre, NORMAL, COLOR_0 and _LEAF_SIZE =
    /// length, width in metres) for engines that draw leaf sprites; .glb/.gltf only.
    #[arg(long)]
    point_leaves: bool,
    /// glb/gltf: store vertex data compactly (KHR_mesh_quantization): positions as 16-bit
    /// integers on a grid per mesh (its largest side over 65,535; one grid for a LoD chain),
    /// normals and tangents 8-bit, texture coordinates 16-bit (outside 0..1 through the material's
    /// KHR_texture_transform), wind data as normalized bytes of their ranges (docs/wind.md). The
    /// quantization is folded into each level's reported error (`stored_error_m`).
    #[arg(long)]
    quantize: bool,
    /// glb/gltf: --quantize, then compress vertex, index and instance data with meshoptimizer's
    /// codecs (EXT_meshopt_compression: lossless; loaders need its decoder, which three.js and
    /// Babylon.js ship).
    #[arg(long)]
    compress: bool,
}

#[derive(Args)]
struct BuildArgs {
    /// Preset files (.toml). None: the embedded demo scene, generated in memory.
    #[arg(value_name = "PRESET")]
    presets: Vec<PathBuf>,
    /// Presets built at the same time. The stages inside share a pool of max(N, --threads) worker
    /// threads; outputs are identical for any N.
    #[arg(long, value_name = "N", default_value_t = 1)]
    jobs: usize,
    /// Build only these stages (comma-separated). Stages not built are absent from the output.
    #[arg(long, value_enum, value_delimiter = ',', value_name = "STAGE,...")]
    only: Vec<Stage>,
    /// Build all stages but these (comma-separated).
    #[arg(long, value_enum, value_delimiter = ',', value_name = "STAGE,...")]
    skip: Vec<Stage>,
    /// Output folder; each scene goes to <DIR>/<scene>/, the stage cache to <DIR>/.cache/.
    #[arg(long, value_name = "DIR", default_value = "out")]
    out: PathBuf,
    /// Ignore the cache and recompute every stage.
    #[arg(long)]
    force: bool,
    /// Also render each scene's first view at full detail (every instance at LoD0, nothing culled)
    /// and report the share of pixels that differ from the view with LoD, and the colour RMSE
    /// (960×540, 4 × 4 samples per pixel resolved as anti-aliasing resolves them; the share of
    /// single samples too). Skipped above 5 G full-detail triangles (said in the report).
    #[arg(long)]
    compare_full_detail: bool,
    /// Build only shard I of N (I/N, 0 ≤ I < N) into --out's cache: its share of the scene's units
    /// (a chunked terrain's bands with the placements of their tile rows, in runs of neighbours;
    /// the terrain stage of an unchunked one and each plant species, unit k to shard k mod N).
    /// With --tiles, the second round: the shard's scene tiles. `verdant merge` then joins the N
    /// shard folders into the scene a single build makes, byte for byte. --only and --skip do not
    /// apply. See docs/sharding.md (GNU parallel, Slurm, Kubernetes).
    #[arg(long, value_name = "I/N")]
    shard: Option<Shard>,
    /// With --shard I/N, after every shard of the first round: the second round, which makes the
    /// scene tiles of shard I's share (`[scene] tile`) from the first round's folders (--shards, all
    /// N); `verdant merge` then puts them in place instead of writing them. Give the same --out as
    /// the shard's first round.
    #[arg(long, requires = "shard", requires = "shards")]
    tiles: bool,
    /// The first round's shard folders (all N), for --tiles.
    #[arg(long, value_name = "DIR", num_args = 1.., requires = "tiles")]
    shards: Vec<PathBuf>,
}

#[derive(Args)]
struct MergeArgs {
    /// Preset files (.toml), as given to the shards. None: the embedded demo scene.
    #[arg(value_name = "PRESET")]
    presets: Vec<PathBuf>,
    /// The shard folders (each the --out of one `verdant build --shard I/N`), all N of them, in any
    /// order.
    #[arg(long, value_name = "DIR", num_args = 1.., required = true)]
    shards: Vec<PathBuf>,
    /// Output folder; each scene goes to <DIR>/<scene>/, as `verdant build` puts it.
    #[arg(long, value_name = "DIR", default_value = "out")]
    out: PathBuf,
    /// Presets merged at the same time (as `verdant build --jobs`).
    #[arg(long, value_name = "N", default_value_t = 1)]
    jobs: usize,
}

#[derive(Subcommand)]
enum CacheCommand {
    /// Remove every cache entry that no scene folder in <DIR> was last built from, and temporary
    /// folders left by builds that were killed.
    Prune {
        /// Output folder whose cache to prune.
        #[arg(long, value_name = "DIR", default_value = "out")]
        out: PathBuf,
    },
    /// Remove the whole cache of <DIR> (the next build recomputes every stage).
    Clean {
        /// Output folder whose cache to remove.
        #[arg(long, value_name = "DIR", default_value = "out")]
        out: PathBuf,
    },
}

#[derive(Subcommand)]
enum PresetCommand {
    /// Parse and check presets (keys, types, values, input files) without building.
    ///
    /// Example: verdant preset check presets/alpine.toml
    Check {
        #[arg(required = true, value_name = "PRESET")]
        files: Vec<PathBuf>,
    },
    /// Write a commented preset template to presets/<NAME>.toml (or --output).
    ///
    /// Example: verdant preset new canyon
    New {
        /// Scene name: letters, digits, - and _.
        name: String,
        /// Where to write the template (default presets/<NAME>.toml); an existing file is not overwritten.
        #[arg(short, long, value_name = "FILE")]
        output: Option<PathBuf>,
    },
}

#[derive(Args)]
struct TerrainArgs {
    /// Heightmap file: PNG or TIFF (gray 8/16-bit, Terrain-RGB, Terrarium, 32-bit float), SRTM .hgt, raw .r16/.raw.
    #[arg(value_name = "HEIGHTMAP", required_unless_present = "demo", conflicts_with = "demo")]
    input: Option<PathBuf>,
    /// Use the embedded procedural heightmap (257×257 samples, 4 m apart, up to 300 m relief) instead of a file.
    #[arg(long)]
    demo: bool,
    /// How pixel values map to metres. auto: .hgt → hgt, .r16/.raw → r16, float TIFF → float, gray or
    /// R=G=B images → gray; colour RGB images must be given terrain-rgb or terrarium explicitly.
    #[arg(long, value_enum, default_value_t = Encoding::Auto)]
    encoding: Encoding,
    /// Size of a raw .r16/.raw file as WIDTHxHEIGHT in samples (a square is inferred when omitted).
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    size: Option<(usize, usize)>,
    /// Distance between neighbouring samples in metres.
    #[arg(long, value_name = "METRES", default_value_t = 1.0)]
    cell_size: f64,
    /// Gray and r16 only: metres spanned by the full value range, y = offset + v / vmax · scale
    /// (vmax = 255 or 65535).
    #[arg(long, value_name = "METRES", default_value_t = 100.0)]
    height_scale: f64,
    /// Gray and r16 only: metres added to every height.
    #[arg(long, value_name = "METRES", default_value_t = 0.0)]
    height_offset: f64,
    /// Refuse maps with more samples than this (checked before decoding, so a huge file is a clear
    /// error instead of an out-of-memory kill).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_SAMPLES)]
    max_samples: usize,
    /// tin: adaptive triangulation within --max-error; grid: every --grid-step samples.
    #[arg(long, value_enum, default_value_t = MeshMode::Tin)]
    mode: MeshMode,
    /// tin: largest allowed vertical distance in metres between the mesh and any heightmap sample.
    #[arg(long, value_name = "METRES", default_value_t = 1.0)]
    max_error: f64,
    /// tin: stop refining at this many triangles; the error then achieved is reported.
    #[arg(long, value_name = "N")]
    max_triangles: Option<usize>,
    /// Meshing work budget: refuse a map predicted to need more vertices than this (checked before meshing,
    /// and while meshing). About 5 s and 250 MB per million vertices on 2 cores.
    #[arg(long, value_name = "N", default_value_t = verdant::terrain::budget::DEFAULT_MAX_VERTICES)]
    max_vertices: usize,
    /// grid: take every N-th sample (1 reproduces the heightmap exactly; the last row and column are always kept).
    #[arg(long, value_name = "N", default_value_t = 1)]
    grid_step: usize,
    /// Split the mesh into chunks of N×N samples, one named node and mesh each (no cracks between them).
    #[arg(long, value_name = "N")]
    chunk: Option<usize>,
    /// Add skirts hanging DEPTH metres down along every chunk border (hides cracks between chunk LoDs).
    #[arg(long, value_name = "METRES")]
    skirt: Option<f64>,
    /// Close the mesh into a watertight solid whose bottom lies DEPTH metres below the lowest sample.
    #[arg(long, value_name = "METRES")]
    base: Option<f64>,
    /// Output file: .glb, .gltf (+ .bin) or .obj (+ .mtl). Default: out/<input name>.glb.
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,
    /// glb/gltf: store positions as 16-bit integers (KHR_mesh_quantization; x, z by the cell, y
    /// over the height range), normals and UVs as 16-bit; --max-error holds for the quantized
    /// vertices. About 40 % smaller files; every engine we test reads them.
    #[arg(long)]
    quantize: bool,
    /// glb/gltf: --quantize, then compress vertex and index data with meshoptimizer's codecs
    /// (EXT_meshopt_compression: lossless, several times smaller; loaders need its decoder:
    /// three.js setMeshoptDecoder, Babylon.js built in, Unity glTFast, Godot 4.2+, Blender 3.6+).
    #[arg(long)]
    compress: bool,
    /// Write a JSON report: sizes, measured max and RMS error, counts and seconds per step.
    #[arg(long, value_name = "FILE.json")]
    report: Option<PathBuf>,
    /// Instead of one mesh, print the speed/error curve: comma-separated thresholds in metres,
    /// e.g. 100,30,10,3,1 (writes no mesh; --report then holds the table).
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    sweep: Option<Vec<f64>>,
}

#[derive(Args)]
struct ValidateArgs {
    /// Files to check (.glb, .gltf, .obj).
    #[arg(required = true, value_name = "FILE")]
    files: Vec<PathBuf>,
    /// Also require every triangle to face up (+Y), as terrain surfaces do.
    #[arg(long)]
    up_facing: bool,
}

fn parse_size(s: &str) -> Result<(usize, usize), String> {
    let (w, h) =
        s.split_once(['x', 'X']).ok_or_else(|| format!("expected WIDTHxHEIGHT such as 1025x1025, got {s:?}"))?;
    let parse =
        |v: &str| v.trim().parse::<usize>().map_err(|_| format!("expected WIDTHxHEIGHT such as 1025x1025, got {s:?}"));
    Ok((parse(w)?, parse(h)?))
}

/// `--threads` above this many per core is refused: threads beyond the cores only switch (5000
/// threads turned a 0.15 s job into a minute).
const MAX_THREADS_PER_CORE: usize = 4;

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(n) = cli.threads {
        if n == 0 {
            return exit(fail("--threads must be at least 1", Blame::Input));
        }
        let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
        if n > MAX_THREADS_PER_CORE * cores {
            let most = MAX_THREADS_PER_CORE * cores;
            let message = format!(
                "--threads {n} is more than {MAX_THREADS_PER_CORE} per core ({cores} cores here); use at most {most}"
            );
            return exit(fail(&message, Blame::Input));
        }
        if let Err(e) = rayon::ThreadPoolBuilder::new().num_threads(n).build_global() {
            return exit(fail(&format!("cannot start {n} threads: {e}"), Blame::Build));
        }
    }
    let code = match cli.command {
        Command::Terrain(args) => terrain(args, cli.quiet),
        Command::Validate(args) => validate(args, cli.quiet),
        Command::Build(args) => build(args, cli.quiet),
        Command::Merge(args) => merge(args, cli.quiet),
        Command::Preset(cmd) => preset(cmd, cli.quiet),
        Command::Cache(cmd) => cache(cmd, cli.quiet),
        Command::Tree(args) => tree(args, cli.quiet),
        Command::Mesh(args) => mesh(args, cli.quiet),
    };
    exit(code)
}

fn exit(code: i32) -> ExitCode {
    ExitCode::from(code as u8)
}

fn cache(cmd: CacheCommand, quiet: bool) -> i32 {
    let (out, pruning) = match &cmd {
        CacheCommand::Prune { out } => (out, true),
        CacheCommand::Clean { out } => (out, false),
    };
    if out.exists() && !out.is_dir() {
        return fail(
            &format!("{}: not a folder; pass the output folder of `verdant build` with --out", out.display()),
            Blame::Input,
        );
    }
    let cache = verdant::scene::cache::Cache::new(out);
    let result = if pruning { cache.prune(out) } else { cache.clean() };
    match result {
        Ok(done) => {
            if !quiet {
                let mb = done.bytes_freed as f64 / 1e6;
                println!(
                    "{}: removed {} entries ({mb:.1} MB), kept {}",
                    cache.root.display(),
                    done.entries_removed,
                    done.entries_kept
                );
            }
            0
        }
        Err(e) => fail(&format!("{}: {e}; check the folder's permissions", cache.root.display()), Blame::Build),
    }
}

fn terrain(a: TerrainArgs, quiet: bool) -> i32 {
    let source = match &a.input {
        Some(p) => Source::File(p.clone()),
        None => Source::Demo,
    };
    let name = match &a.input {
        Some(p) => p.file_stem().and_then(|s| s.to_str()).unwrap_or("terrain").to_string(),
        None => "demo".to_string(),
    };
    let job = TerrainJob {
        source,
        decode: DecodeOptions {
            encoding: a.encoding,
            size: a.size,
            cell_size_m: a.cell_size,
            height_scale_m: a.height_scale,
            height_offset_m: a.height_offset,
            max_samples: a.max_samples,
        },
        mode: a.mode,
        grid_step: a.grid_step,
        max_error_m: a.max_error,
        max_triangles: a.max_triangles,
        max_vertices: a.max_vertices,
        build: BuildOptions {
            chunk_samples: a.chunk,
            skirt_depth_m: a.skirt,
            base_depth_m: a.base,
            name: name.clone(),
            snow: Default::default(),
        },
        quantize: a.quantize || a.compress,
        meshopt: a.compress,
    };
    if let Some(thresholds) = &a.sweep {
        return match job::sweep(&job, thresholds) {
            Ok((decoded, rows)) => {
                if !quiet {
                    let hf = &decoded.heightfield;
                    println!(
                        "{}: {}×{} samples, encoding {}",
                        job.source.label(),
                        hf.width,
                        hf.height,
                        decoded.encoding
                    );
                    print!("{}", job::sweep_table(&rows));
                }
                match &a.report {
                    Some(path) => match job::write_json(path, &rows) {
                        Ok(()) => 0,
                        Err(e) => failed(&e),
                    },
                    None => 0,
                }
            }
            Err(e) => failed(&e),
        };
    }
    let output = a.output.clone().unwrap_or_else(|| PathBuf::from("out").join(format!("{name}.glb")));
    if let Err(e) = verdant::export::check_output_path(&output) {
        return failed(&e);
    }
    if (a.quantize || a.compress) && output.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj")) {
        return fail(
            &format!("{}: --quantize and --compress store glTF integer positions (KHR_mesh_quantization), which an .obj cannot hold; write .glb or .gltf, or leave them out", output.display()),
            Blame::Input,
        );
    }
    // the mesh files and the report are replaced together
    match job::run_reporting(&job, Some(&output), a.report.as_deref()) {
        Ok((report, _scene)) => {
            if !quiet {
                let out = report.output.as_ref();
                println!(
                    "{}: {}×{} samples ({}) → {} triangles ({:.2}% of the full grid), max error {} m as written (requested {}; {} m in f64), rms {:.3} m, {:.2} s",
                    report.input,
                    report.figures.width,
                    report.figures.height,
                    report.encoding,
                    report.figures.triangles,
                    100.0 * report.figures.triangles as f64 / report.figures.full_grid_triangles.max(1) as f64,
                    metres(report.figures.max_error),
                    report.figures.max_error_requested.map_or("—".to_string(), |e| format!("{e} m")),
                    metres(report.figures.max_error_f64),
                    report.figures.rms_error,
                    report.seconds.total
                );
                if report.figures.hit_triangle_limit {
                    println!(
                        "  stopped at --max-triangles; the achieved max error is {:.3} m",
                        report.figures.max_error
                    );
                }
                if report.figures.voids_filled > 0 {
                    println!("  filled {} void samples from their neighbours", report.figures.voids_filled);
                }
                for f in out.map(|o| o.files.as_slice()).unwrap_or(&[]) {
                    println!("  wrote {f}");
                }
            }
            0
        }
        Err(e) => failed(&e),
    }
}

fn validate(a: ValidateArgs, quiet: bool) -> i32 {
    let opts = ValidateOptions { up_facing: a.up_facing };
    let mut worst = 0;
    for file in &a.files {
        match validate_file(file, &opts) {
            Ok(report) => {
                if !report.ok() {
                    // a file that does not validate: the build that wrote it failed
                    worst = worst.max(Blame::Build.exit_code());
                    eprintln!("{report}");
                } else if !quiet {
                    println!("{report}");
                }
            }
            // a file that cannot be read or parsed at all is bad input (and the worst outcome)
            Err(e) => worst = worst.max(fail(&e.to_string(), Blame::Input)),
        }
    }
    worst
}

/// The one exit mapping of every subcommand: prints the message, returns the exit code of whose
/// fault it is (2 bad input or usage, 1 a failure of the build, its writing or validation).
fn fail(message: &str, blame: Blame) -> i32 {
    eprintln!("error: {message}");
    blame.exit_code()
}

/// [`fail`] with a typed error's own message and blame.
fn failed(e: &dyn Failure) -> i32 {
    fail(&e.to_string(), e.blame())
}

fn build(a: BuildArgs, quiet: bool) -> i32 {
    let mut stages: Vec<Stage> = if a.only.is_empty() { Stage::ALL.to_vec() } else { a.only.clone() };
    stages.retain(|s| !a.skip.contains(s));
    if stages.is_empty() {
        return fail("--only/--skip leave no stage to build", Blame::Input);
    }
    for s in [Stage::Snow, Stage::Scatter, Stage::Preview] {
        if stages.contains(&s) && !stages.contains(&Stage::Terrain) {
            return fail(
                &format!("the {0} stage needs the terrain stage: add it (--only terrain,{0})", s.name()),
                Blame::Input,
            );
        }
    }
    let sources: Vec<PresetSource> = if a.presets.is_empty() {
        vec![PresetSource::Resolved(Box::new(preset::demo_preset()))]
    } else {
        a.presets.iter().cloned().map(PresetSource::File).collect()
    };
    let settings = BuildSettings {
        out_dir: a.out.clone(),
        stages,
        force: a.force,
        compare_full_detail: a.compare_full_detail,
        shard: a.shard,
        merging: false,
        tiles_from: if a.tiles { a.shards.clone() } else { Vec::new() },
        tile_scenes: Vec::new(),
    };
    let progress = scene_build::ProgressView::new(quiet);
    let outcomes =
        scene_build::build_batch(&sources, &settings, a.jobs, &|scene: &str, msg: &str| progress.update(scene, msg));
    progress.finish();
    report_outcomes(&outcomes, quiet)
}

fn merge(a: MergeArgs, quiet: bool) -> i32 {
    let sources: Vec<PresetSource> = if a.presets.is_empty() {
        vec![PresetSource::Resolved(Box::new(preset::demo_preset()))]
    } else {
        a.presets.iter().cloned().map(PresetSource::File).collect()
    };
    let settings = BuildSettings { out_dir: a.out.clone(), ..BuildSettings::default() };
    let progress = scene_build::ProgressView::new(quiet);
    let outcomes = scene_build::merge_batch(&sources, &a.shards, &settings, a.jobs, &|scene: &str, msg: &str| {
        progress.update(scene, msg)
    });
    progress.finish();
    report_outcomes(&outcomes, quiet)
}

/// Prints the batch's table (to stderr when a scene failed) and its warnings; the exit code.
fn report_outcomes(outcomes: &[scene_build::SceneOutcome], quiet: bool) -> i32 {
    let table = scene_build::summary_table(outcomes);
    let failed = outcomes.iter().any(|o| o.error.is_some());
    if failed {
        eprint!("{table}");
    } else if !quiet {
        print!("{table}");
    }
    for o in outcomes {
        for w in &o.warnings {
            eprintln!("warning: scene `{}`: {w}", o.scene);
        }
    }
    scene_build::batch_blame(outcomes).map_or(0, Blame::exit_code)
}

fn preset(cmd: PresetCommand, quiet: bool) -> i32 {
    match cmd {
        PresetCommand::Check { files } => {
            let mut code = 0;
            for f in &files {
                match preset::check_preset(f) {
                    Ok(p) => {
                        let over = preset::instance_estimates_over_limit(&p);
                        // the preset's text again only to place a warning
                        let text = if over.is_empty() {
                            String::new()
                        } else {
                            std::fs::read_to_string(f).unwrap_or_default()
                        };
                        for (name, estimate, limit) in over {
                            // at the species' max_density (the figure the estimate comes from)
                            let index = p.species.iter().position(|s| s.rules.name == name).unwrap_or(0);
                            let at = match preset::species_key_position(&text, index, "max_density") {
                                Some((line, column)) => format!("{}:{line}:{column}", f.display()),
                                None => f.display().to_string(),
                            };
                            eprintln!(
                                "warning: {at}: species `{name}` may place up to ~{estimate:.0} instances (max_density over the whole terrain), \
                                 above its max_instances {limit}: the build fails if its rules allow more than {limit}; \
                                 lower max_density, narrow the rules or raise max_instances"
                            );
                        }
                        for w in preset::lsystem_warnings(&p) {
                            eprintln!("warning: {}: {w}", f.display());
                        }
                        if !quiet {
                            println!("{}: ok (scene `{}`)", f.display(), p.scene.name);
                        }
                    }
                    Err(e) => code = failed(&e),
                }
            }
            code
        }
        PresetCommand::New { name, output } => {
            let path = output.unwrap_or_else(|| PathBuf::from("presets").join(format!("{name}.toml")));
            if path.exists() {
                return fail(
                    &format!("{} exists; choose another name or --output, it is not overwritten", path.display()),
                    Blame::Input,
                );
            }
            let text = preset::template(&name);
            if let Err(e) = preset::parse_preset(&text, &path) {
                return fail(&format!("cannot make a template named `{name}`: {e}"), Blame::Input);
            }
            match verdant::export::write_atomic(&path, text.as_bytes()) {
                Ok(()) => {
                    if !quiet {
                        println!("wrote {}", path.display());
                    }
                    0
                }
                Err(e) => fail(&e.to_string(), Blame::Build),
            }
        }
    }
}

fn tree(a: TreeArgs, quiet: bool) -> i32 {
    // `builtin:<name>`: a tree of the built-in library, named after it and grown to its height
    let builtin = match verdant::lsystem::library::named(&a.input) {
        Some(Ok(species)) => Some(species),
        Some(Err(names)) => {
            return fail(
                &format!(
                    "{}: no built-in L-system of that name; built-in: {names} (e.g. builtin:conifer)",
                    a.input.display()
                ),
                Blame::Input,
            )
        }
        None => None,
    };
    let name = match builtin {
        Some(species) => species.name.to_string(),
        None => a.input.file_stem().and_then(|s| s.to_str()).unwrap_or("tree").to_string(),
    };
    let job = TreeJob {
        output: a.output.clone().unwrap_or_else(|| PathBuf::from("out").join(format!("{name}.glb"))),
        input: a.input.clone(),
        dialect: match a.dialect {
            DialectArg::Auto => None,
            DialectArg::Ls => Some(Dialect::Stochastic),
            DialectArg::V4 => Some(Dialect::LparserV4),
            DialectArg::V5 => Some(Dialect::LparserV5),
        },
        options: TreeOptions {
            seed: a.seed,
            radial_segments: a.radial_segments,
            max_symbols: a.max_symbols,
            max_segments: a.max_segments,
            max_triangles: a.max_triangles,
            metres_per_step: a.step,
            height_m: a.height.or(builtin.map(|s| s.height_m)),
            leaf_points: a.point_leaves,
            name,
            ..TreeOptions::default()
        },
        compact: Compact::from_flags(a.quantize, a.compress),
    };
    if let Err(e) = verdant::export::check_output_path(&job.output) {
        return failed(&e);
    }
    let glb = job.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    let lods = a.lods.unwrap_or(if glb { tree_lod::TREE_LODS } else { 1 });
    // `--lods 1` on a .glb still writes the (one-level) chain and its report; on .gltf/.obj it is
    // the single mesh, as the chain's own error message suggests
    if lods > 1 || a.variants > 1 || (a.lods.is_some() && glb) {
        let lod_job = TreeLodJob {
            input: job.input.clone(),
            output: job.output.clone(),
            dialect: job.dialect,
            options: job.options.clone(),
            lod: TreeLodOptions {
                lods,
                atlas_px: a.atlas_size,
                analyze: !a.no_analysis,
                compact: job.compact,
                ..TreeLodOptions::default().with_analysis(a.analysis.detail())
            },
            variants: a.variants,
        };
        // each step of the chain as it starts: a spinner on a terminal, plain lines otherwise
        let view = verdant::progress::ProgressView::new(quiet);
        let task = lod_job.options.name.clone();
        // the chain's files and the report are replaced together
        let result = tree_lod::run_lods_reporting(&lod_job, a.report.as_deref(), &|step| view.update(&task, step));
        view.finish();
        return match result {
            Ok(report) => {
                if !quiet {
                    print_tree_summary(&report.tree);
                    for v in &report.variants {
                        print_lod_table(v);
                    }
                    for f in &report.tree.files {
                        println!("  wrote {f}");
                    }
                }
                0
            }
            Err(e) => failed(&e),
        };
    }
    // the tree's files and the report are replaced together
    match tree_job::run_reporting(&job, a.report.as_deref()) {
        Ok(report) => {
            if !quiet {
                print_tree_summary(&report);
                for f in &report.files {
                    println!("  wrote {f}");
                }
            }
            0
        }
        Err(e) => failed(&e),
    }
}

fn print_lod_table(v: &tree_lod::TreeLodReport) {
    println!("  {}: level triangles bytes hausdorff_max_m (as stored) switch_m", v.name);
    for l in &v.lods {
        println!(
            "    LoD{} {:<10} {:>8} {:>9} {:>10.4} {:>9.1}{}",
            l.level,
            l.kind,
            l.triangles,
            l.bytes,
            l.stored_error_m,
            l.switch_distance_m,
            if l.never_passes { " (never passes)" } else { "" }
        );
    }
    for o in &v.left_out {
        println!(
            "    left out: the {} level ({} triangles, not fewer than the {} before it), so the chain has {} levels",
            o.kind,
            o.triangles,
            o.previous_triangles,
            v.lods.len()
        );
    }
}

fn mesh(a: MeshArgs, quiet: bool) -> i32 {
    let name = a.input.file_stem().and_then(|s| s.to_str()).unwrap_or("mesh").to_string();
    let job = MeshLodJob {
        output: a.output.clone().unwrap_or_else(|| PathBuf::from("out").join(format!("{name}.glb"))),
        input: a.input.clone(),
        obj: ObjOptions {
            scale: a.scale,
            up_axis: match a.up_axis {
                UpAxisArg::Y => UpAxis::Y,
                UpAxisArg::Z => UpAxis::Z,
            },
            max_vertices: a.max_vertices,
            max_triangles: a.max_triangles,
            ..ObjOptions::default()
        },
        lod: TreeLodOptions {
            lods: a.lods,
            atlas_px: a.atlas_size,
            analyze: !a.no_analysis,
            compact: Compact::from_flags(a.quantize, a.compress),
            ..TreeLodOptions::default().with_analysis(a.analysis.detail())
        },
    };
    if let Err(e) = verdant::export::check_output_path(&job.output) {
        return failed(&e);
    }
    let view = verdant::progress::ProgressView::new(quiet);
    let task = job.input.file_stem().map_or_else(|| "mesh".into(), |s| s.to_string_lossy().into_owned());
    // the chain's files and the report are replaced together
    let result = tree_lod::run_mesh_lods_reporting(&job, a.report.as_deref(), &|step| view.update(&task, step));
    view.finish();
    match result {
        Ok(report) => {
            if !quiet {
                let s = &report.source;
                println!(
                    "{}: {} vertices, {} triangles in {} primitives, {} materials, {} textures{}, {:.3} s",
                    report.input,
                    s.vertices,
                    s.triangles,
                    s.primitives,
                    s.materials,
                    s.textures,
                    if s.normals_generated > 0 { ", normals generated" } else { "" },
                    report.seconds_total
                );
                print_lod_table(&report.chain);
                for f in &report.files {
                    println!("  wrote {f}");
                }
            }
            0
        }
        Err(e) => failed(&e),
    }
}

fn print_tree_summary(report: &tree_job::TreeReport) {
    let s = &report.stats;
    println!(
        "{} ({}{}): {} symbols → {} segments, {} leaves, {} polygons → {} triangles in {} primitives, {} branch levels, height {:.2} m, {:.3} s",
        report.input,
        report.dialect,
        if report.dialect_detected { ", detected" } else { "" },
        s.symbols,
        s.segments,
        s.leaves,
        s.polygons,
        s.triangles,
        s.primitives,
        s.max_branch_level + 1,
        s.height_m,
        report.seconds.to_lod0
    );
    for w in &report.warnings {
        println!("  warning: {w}");
    }
}

/// A measured error for a terminal: six significant digits, so a figure just over a bound shows.
fn metres(m: f64) -> String {
    if m == 0.0 {
        "0".into()
    } else {
        let digits = (5 - m.abs().log10().floor() as i32).clamp(0, 12) as usize;
        format!("{m:.digits$}")
    }
}
