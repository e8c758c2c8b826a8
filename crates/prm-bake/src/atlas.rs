//! `prm-bake atlas`: scene and lightmap-atlas statistics, optionally a picture of the charts.

use anyhow::{Context, Result};
use prm_scene::{Atlas, AtlasParams, Light, Scene, Sizing, EMPTY_TEXEL};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `prm-bake atlas`.
#[derive(clap::Args)]
pub struct AtlasArgs {
    /// Scene file: .obj (with its .mtl), .gltf or .glb.
    pub scene: PathBuf,
    /// Texel edge length in scene units; the atlas resolution follows from it.
    #[arg(long, conflicts_with = "resolution")]
    pub texel_size: Option<f32>,
    /// Atlas resolution (texels on a side); the texel size follows from it.
    /// Without this or --texel-size the resolution is chosen from the triangle and chart counts.
    #[arg(long)]
    pub resolution: Option<u32>,
    /// Empty texels around every chart (two charts are at least twice this apart).
    #[arg(long, default_value_t = AtlasParams::DEFAULT.gutter)]
    pub gutter: u32,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Draw the charts into this PNG (one colour per chart, gutters darker, empty texels black).
    #[arg(long, value_name = "FILE")]
    pub png: Option<PathBuf>,
}

pub fn run(args: &AtlasArgs) -> Result<()> {
    let built = build(args)?;
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&json_report(&built))?);
        return Ok(());
    }
    print_scene(&built.scene);
    print_atlas(&built);
    outln!("time         load {:.3} s, atlas {:.3} s", built.load_s, built.atlas_s);
    if let Some(png) = &args.png {
        outln!("charts drawn {}", png.display());
    }
    Ok(())
}

/// A loaded scene, its atlas, and the seconds each took.
struct Built {
    scene: Scene,
    atlas: Atlas,
    load_s: f64,
    atlas_s: f64,
}

/// Loads the scene and builds its atlas as `args` ask, warning on stderr, and draws the charts
/// where asked.
fn build(args: &AtlasArgs) -> Result<Built> {
    let t0 = Instant::now();
    let scene = prm_scene::load(&args.scene).with_context(|| format!("loading {}", args.scene.display()))?;
    let load_s = t0.elapsed().as_secs_f64();
    for w in &scene.report.warnings {
        eprintln!("warning: {w}");
    }
    let sizing = match (args.texel_size, args.resolution) {
        (Some(s), _) => Sizing::TexelSize(s),
        (None, Some(r)) => Sizing::Resolution(r),
        (None, None) => Sizing::Auto,
    };
    let params = AtlasParams {
        sizing,
        gutter: args.gutter,
        ..AtlasParams::DEFAULT
    };
    let t1 = Instant::now();
    let atlas = Atlas::build(&scene, &params).context("building the lightmap atlas")?;
    let atlas_s = t1.elapsed().as_secs_f64();
    if let Some(w) = atlas.coverage_warning(scene.triangles.len()) {
        eprintln!("warning: {w}");
    }
    if let Some(png) = &args.png {
        draw_charts(&atlas)
            .save(png)
            .with_context(|| format!("writing {}", png.display()))?;
    }
    Ok(Built {
        scene,
        atlas,
        load_s,
        atlas_s,
    })
}

/// The scene's lights of each kind.
struct LightCounts {
    point: usize,
    spot: usize,
    directional: usize,
}

impl LightCounts {
    fn of(scene: &Scene) -> LightCounts {
        let count = |f: fn(&Light) -> bool| scene.lights.iter().filter(|l| f(l)).count();
        LightCounts {
            point: count(|l| matches!(l, Light::Point { .. })),
            spot: count(|l| matches!(l, Light::Spot { .. })),
            directional: count(|l| matches!(l, Light::Directional { .. })),
        }
    }
}

/// The `--json` report: the scene's and the atlas's statistics in one object.
fn json_report(built: &Built) -> serde_json::Value {
    let (scene, s) = (&built.scene, &built.atlas.stats);
    let bounds = scene.bounds();
    let lights = LightCounts::of(scene);
    serde_json::json!({
        "scene": scene.source,
        "triangles": scene.triangles.len(),
        "degenerate_dropped": scene.report.degenerate_dropped,
        "duplicates_dropped": scene.report.duplicates_dropped,
        "materials": scene.materials.len(),
        "textures": scene.textures.len(),
        "area": scene.area(),
        "bounds": { "min": bounds.min.to_array(), "max": bounds.max.to_array() },
        "lights": {
            "point": lights.point,
            "spot": lights.spot,
            "directional": lights.directional,
        },
        "emissive_materials": scene.emissive_materials(),
        "cameras": scene.cameras.len(),
        "fingerprint": format!("{:016x}", scene.fingerprint()),
        "lightmap_uvs_from_file": scene.lightmap_uvs.is_some(),
        "charts": s.charts,
        "resolution": s.resolution,
        "texel_size": s.texel_size,
        "utilization": s.utilization,
        "covered_texels": s.covered_texels,
        "dilated_texels": s.dilated_texels,
        "uncovered_triangles": s.uncovered_triangles,
        "triangles_without_exit": s.triangles_without_exit,
        "texels_per_triangle": { "min": s.texels_per_triangle_min, "median": s.texels_per_triangle_median },
        "overlapping_texels": s.overlapping_texels,
        "shared_texels": s.shared_texels,
        "warnings": scene.report.warnings,
        "seconds": { "load": built.load_s, "atlas": built.atlas_s },
    })
}

/// Prints the scene's statistics: triangles, materials, extent, lights, emitters, fingerprint.
fn print_scene(scene: &Scene) {
    let bounds = scene.bounds();
    let e = bounds.extent();
    outln!("scene        {}", scene.source.display());
    outln!(
        "triangles    {} ({} degenerate, {} duplicates dropped)",
        scene.triangles.len(),
        scene.report.degenerate_dropped,
        scene.report.duplicates_dropped
    );
    outln!(
        "materials    {} ({} textures)",
        scene.materials.len(),
        scene.textures.len()
    );
    outln!("area         {:.4} square units", scene.area());
    outln!(
        "bounds       [{:.3} {:.3} {:.3}] .. [{:.3} {:.3} {:.3}] (extent {:.3} x {:.3} x {:.3})",
        bounds.min.x,
        bounds.min.y,
        bounds.min.z,
        bounds.max.x,
        bounds.max.y,
        bounds.max.z,
        e.x,
        e.y,
        e.z
    );
    let lights = LightCounts::of(scene);
    outln!(
        "lights       {} point, {} spot, {} directional; {} cameras",
        lights.point,
        lights.spot,
        lights.directional,
        scene.cameras.len()
    );
    let emissive = scene.emissive_materials();
    if !emissive.is_empty() {
        outln!("emitters     {} (emissive materials)", emissive.join(", "));
    }
    outln!("fingerprint  {:016x}", scene.fingerprint());
}

/// Prints the atlas's statistics: size, charts, coverage, texels per triangle, overlaps.
fn print_atlas(built: &Built) {
    let s = &built.atlas.stats;
    outln!(
        "atlas        {r}x{r}, texel size {:.4}, {} charts{}",
        s.texel_size,
        s.charts,
        if built.scene.lightmap_uvs.is_some() {
            " (lightmap UVs from the file)"
        } else {
            ""
        },
        r = s.resolution
    );
    outln!(
        "texels       {} covered ({:.1}% utilisation), {} gutter texels dilated",
        s.covered_texels,
        100.0 * s.utilization,
        s.dilated_texels
    );
    outln!(
        "per triangle min {}, median {} exit texels; {} triangles own none, {} touch none",
        s.texels_per_triangle_min,
        s.texels_per_triangle_median,
        s.triangles_without_exit,
        s.uncovered_triangles
    );
    if s.overlapping_texels > 0 || s.shared_texels > 0 {
        outln!(
            "overlaps     {} folded texels, {} texels shared by charts",
            s.overlapping_texels,
            s.shared_texels
        );
    }
}

/// One colour per chart (hashed from its index); gutters at half brightness; empty texels black.
fn draw_charts(atlas: &Atlas) -> image::RgbImage {
    let r = atlas.resolution;
    let colour = |chart: u32| {
        let h = (chart as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        [
            64 + (h >> 8) as u8 % 192,
            64 + (h >> 24) as u8 % 192,
            64 + (h >> 40) as u8 % 192,
        ]
    };
    // Texel row 0 is v = 0; draw it at the bottom so the picture matches UV space.
    image::RgbImage::from_fn(r, r, |x, y| {
        let i = ((r - 1 - y) * r + x) as usize;
        let chart = atlas.texel_chart[i];
        if chart == EMPTY_TEXEL {
            image::Rgb([0, 0, 0])
        } else if atlas.texel_exit[i] == EMPTY_TEXEL {
            image::Rgb(colour(chart).map(|c| c / 2))
        } else {
            image::Rgb(colour(chart))
        }
    })
}
