//! The commented preset `verdant preset new` writes.

/// `verdant preset new NAME`: a fully commented preset that parses as it is (a procedural
/// terrain, so it builds without any input file). `name` should pass [`super::keys::check_scene_name`].
pub fn template(name: &str) -> String {
    let escaped: String = name
        .chars()
        .flat_map(|c| match c {
            '"' => vec!['\\', '"'],
            '\\' => vec!['\\', '\\'],
            c if c.is_control() => vec!['_'],
            c => vec![c],
        })
        .collect();
    TEMPLATE.replace("{NAME}", &escaped)
}

pub(super) const TEMPLATE: &str = r#"# verdant preset — every key is documented in docs/presets.md.
# Check it with `verdant preset check FILE`, build it with `verdant build FILE`.
# Paths are relative to this file's folder. Lengths are in metres.

[scene]
# Output folder name under out/: letters, digits, `-` and `_` only.
name = "{NAME}"
# Global seed: every random choice of the build derives from it (same seed, same files).
seed = 0
# Mesh formats written, first = primary: "glb", "gltf" (+ .bin), "obj" (+ .mtl).
formats = ["glb"]
# How species files, scene.glb and scene_lod.glb store vertex data: "none" (f32), "quantize"
# (16-bit positions, KHR_mesh_quantization), "compress" (+ EXT_meshopt_compression).
compact = "none"

[terrain]
# Heights come from EITHER a heightmap file OR a procedural map (exactly one of the two).
#
# A heightmap file and how to decode it (the meanings of `verdant terrain`'s options):
# heightmap = "heights/valley.png"
# encoding = "auto"          # auto, gray, terrain-rgb, terrarium, hgt, r16, float
# size = [1025, 1025]        # width, height of a raw .r16/.raw file (square if omitted)
# height_scale = 100.0       # gray / r16: metres spanned by the full value range
# height_offset = 0.0        # gray / r16: metres added to every height
# max_samples = 67125249     # refuse larger maps (8193²)
#
# A generated square map: kind "fbm" (rolling) or "ridged" (sharp crests), `size` samples a
# side (2..=8193), heights normalised to 0..`relief` metres; `seed` defaults to [scene] seed.
procedural = { kind = "fbm", size = 513, seed = 7, relief = 200.0 }
# Metres between neighbouring samples (both sources).
cell_size = 2.0

# Meshing: "tin" (adaptive, every sample within max_error) or "grid" (every grid_step-th sample).
mode = "tin"
max_error = 1.0              # tin: largest vertical error allowed at any sample, metres
# max_triangles = 200000     # tin: stop early at this many triangles (achieved error reported)
# grid_step = 1              # grid: keep every N-th sample
# max_vertices = 2097152     # work budget: refuse maps that need more vertices (before meshing)

# Split into chunk×chunk-sample tiles (crack-free), one mesh each.
chunk = 128
# Skirts this deep along every chunk border hide cracks between neighbouring LoDs.
skirt = 2.0
# base = 20.0                # close into a watertight solid this far below the lowest sample
# A LoD chain per chunk: the max error of each level, finest first, strictly increasing.
lods = [1.0, 4.0, 16.0]

# [scatter]
# tile = 256.0               # side of a placement tile, metres
# table = "csv"              # placement tables: "csv", or "binary" (little-endian arrays, for dense species)

# Vegetation: one [[species]] table per species, placed in file order; a species can keep clear
# only of species declared above it (or of itself). Uncomment to scatter trees and grass.
#
# [[species]]
# name = "pine"              # letters, digits, `-` and `_`; names placements/pine.csv
# kind = "tree"              # "grass", "flower", "tree" or "mesh"
# max_density = 0.005        # instances per m² where the density map is 1 (required)
# # density_map = "maps/forest.png"  # grayscale over the terrain: 0..1 scales max_density
# # mask = "maps/no-roads.png"       # grayscale: nothing where it is below 0.5
# placement = "poisson"      # "poisson" (default for trees) or "jittered" (default otherwise)
# min_spacing = 5.0          # metres between two instances (required > 0 for poisson; trees: 4)
# slope = [0.0, 35.0]        # allowed slope, degrees (default [0, 90])
# altitude = [0.0, 150.0]    # allowed height, metres (default: unbounded)
# # water_level = 2.0        # nothing below this height, metres
# scale = [0.8, 1.2]         # uniform scale range (default [1, 1])
# random_yaw = true          # random turn about the vertical (default true)
# align_to_normal = 0.0      # 0 upright … 1 along the ground normal (default: grass/flower 1, else 0)
# seed = 0                   # offset added to the scene seed for this species
# max_instances = 5000000    # more than this is an error naming the species
# # lsystem = "trees/pine.ls"        # grow the trees from this L-system; "builtin:conifer" (or
# #                                   # broadleaf, birch, bush) or none: a built-in tree
# # tree = { variants = 3, height = 14.0 }  # see docs/presets.md, section [tree]
#
# [[species]]
# name = "grass"
# kind = "grass"
# max_density = 0.2
# slope = [0.0, 30.0]
# # keep 1.5 m clear around every pine (an array of such tables lists several species)
# exclusion = { species = "pine", radius = 1.5 }

# Snow: a flake atlas, a particle emitter for the engine, a frozen frame of the fall, and snow
# cover on the terrain that thins grass and flowers (written to snow/). Uncomment to add it.
#
# [snow]
# seed = 0                   # default: derived from the scene seed
# temperature_c = -15.0      # where crystals grow, −40..+2 °C: picks the habits (see docs/snow.md)
# humidity = 0.6             # 0 dry … 1 saturated: plates vs dendrites, flake sizes
# atlas_cells = [4, 4]       # flake atlas columns, rows (1..32 each)
# cell_px = 64               # pixels a cell side (16..1024)
# alpha_cutoff = 0.5         # alpha-test threshold of the flake material
# near_radius = 15.0         # r1: cylinder around the camera holding near_count flakes, m
# near_count = 4000          # N1
# far_radius = 60.0          # r2 > r1: far field out to here, only inside the view angle, m
# far_count = 6000           # N2 (0: no far field)
# view_angle = 90.0          # horizontal view angle of the far field, degrees
# fall_height = 20.0         # flakes live from the ground up to here, m
# wind_direction = [1.0, 0.0]  # [x, z] the wind blows towards (also scours windward snow)
# wind_speed = 1.5           # m/s
# flake_mass = 3e-6          # kg; terminal velocity v = m·g/drag
# drag = 3e-5                # linear drag coefficient k, kg/s
# ground_slowdown = 0.5      # below this height flakes slow down, m …
# ground_speed_factor = 0.3  # … to this fraction of their speed at the ground
# respawn = "top"            # "top" or "wrap_vertical"
# max_spin = 1.0             # sprite spin, rad/s
# snow_line = 100.0          # altitude of half cover, m
# snow_line_noise = 10.0     # the snow line wanders this much up and down, m …
# noise_scale = 200.0        # … over this horizontal wavelength, m
# transition = 10.0          # height over which cover goes from none to full, m
# full_slope = 25.0          # full cover up to this slope, degrees …
# max_slope = 50.0           # … and none from this slope on
# wind_scour = 0.5           # 0..1: how bare faces turned into the wind are
# depth = 0.3                # snow depth at full cover, m
# mask_px = 512              # cover_mask.png's long side, pixels
# layer = true               # write snow_layer.glb (the snow surface lifted by its depth)
# layer_min_weight = 0.5     # the layer keeps triangles at least this covered
# thin_plants = 0.8          # grass/flowers dropped with probability thin_plants × cover weight
"#;
