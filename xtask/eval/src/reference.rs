//! Ground truth from `prm_trace::ReferenceTracer`, cached under target/eval/refs keyed by everything it depends on.

use anyhow::{bail, Context, Result};
use glam::Vec3;
use prm_scene::{Camera, ExitPoint, Light, Scene};
use prm_trace::{Bvh, ImageMode, Lighting, ReferenceParams, ReferenceTracer};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A reference estimate: mean and variance of the mean per texel or pixel.
#[derive(Clone, Debug)]
pub struct Reference {
    pub mean: Vec<Vec3>,
    pub variance: Vec<Vec3>,
    /// Seconds it took (0 when read from the cache).
    pub seconds: f64,
}

fn save(path: &Path, r: &Reference) -> Result<()> {
    let mut bytes = Vec::with_capacity(8 + r.mean.len() * 24);
    bytes.extend_from_slice(&(r.mean.len() as u64).to_le_bytes());
    for v in r.mean.iter().chain(&r.variance) {
        for c in v.to_array() {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
    }
    let tmp = path.with_extension("tmp");
    std::fs::File::create(&tmp)?.write_all(&bytes)?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}

fn load(path: &Path) -> Result<Reference> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)?.read_to_end(&mut bytes)?;
    if bytes.len() < 8 {
        bail!("{} is truncated", path.display());
    }
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    if bytes.len() != 8 + n * 24 {
        bail!("{} has the wrong size", path.display());
    }
    let f: Vec<f32> = bytes[8..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let v: Vec<Vec3> = f.chunks_exact(3).map(Vec3::from_slice).collect();
    Ok(Reference {
        mean: v[..n].to_vec(),
        variance: v[n..].to_vec(),
        seconds: 0.0,
    })
}

/// Part of every cached image reference's key: bump it when the tracer's camera images change,
/// so cached image references are traced again.
pub const IMAGE_EPOCH: u32 = 3;

/// What identifies `scene` (loaded from `path`) in the cache keys: its path, geometry and
/// materials fingerprint and file size.
pub fn scene_key(path: &Path, scene: &Scene) -> String {
    format!(
        "{}|{:016x}|{}",
        path.display(),
        scene.fingerprint(),
        std::fs::metadata(path).map(|m| m.len()).unwrap_or(0)
    )
}

/// Reference computations for one scene, cached in `dir`.
pub struct Tracer<'a> {
    pub scene: &'a Scene,
    pub bvh: Bvh,
    /// Identifies the scene's geometry and materials in cache keys.
    pub scene_key: String,
    pub dir: PathBuf,
}

impl<'a> Tracer<'a> {
    pub fn new(scene: &'a Scene, scene_key: String, dir: PathBuf) -> Result<Self> {
        std::fs::create_dir_all(&dir)?;
        let bvh = Bvh::build(scene, &Default::default()).context("building the BVH")?;
        Ok(Tracer {
            scene,
            bvh,
            scene_key,
            dir,
        })
    }

    fn cached(&self, key: &str, compute: impl FnOnce() -> Result<Reference>) -> Result<Reference> {
        let hash = xxhash_rust::xxh3::xxh3_64(format!("{}|{key}", self.scene_key).as_bytes());
        let path = self.dir.join(format!("{hash:016x}.ref"));
        if let Ok(r) = load(&path) {
            return Ok(r);
        }
        let t = Instant::now();
        let mut r = compute()?;
        r.seconds = t.elapsed().as_secs_f64();
        save(&path, &r).with_context(|| format!("writing {}", path.display()))?;
        Ok(r)
    }

    /// The bake's atlas of resolution `resolution`: the exit points as `prm-bake bake` traces
    /// from them, the buried ones moved within their texel or to a neighbour's point
    /// (`prm_trace::unbury_exits`).
    pub fn atlas(&self, resolution: u32) -> Result<prm_scene::Atlas> {
        let sizing = prm_scene::AtlasParams::with_sizing(prm_scene::Sizing::Resolution(resolution));
        Ok(prm_trace::bake_atlas(self.scene, &self.bvh, &sizing)?)
    }

    /// Indirect irradiance at the exit points of an atlas of resolution `resolution`.
    pub fn lightmap(
        &self,
        resolution: u32,
        exits: &[ExitPoint],
        light_spec: &str,
        light: &Light,
        spp: u32,
    ) -> Result<Reference> {
        // Keyed by the exit points themselves, so that a change to the bake's rules for them
        // (buried ones moved, shut-in ones given a neighbour's point) is never read stale.
        let mut h = std::collections::hash_map::DefaultHasher::new();
        for x in exits {
            for v in x.position.to_array().into_iter().chain(x.normal.to_array()) {
                std::hash::Hasher::write_u32(&mut h, v.to_bits());
            }
        }
        let exits_hash = std::hash::Hasher::finish(&h);
        let key = format!(
            "lightmap|{resolution}|{}|{exits_hash:016x}|{light_spec}|{spp}",
            exits.len()
        );
        self.cached(&key, || {
            let lights = [*light];
            let t = ReferenceTracer::new(self.scene, &self.bvh, Lighting::Lights(&lights));
            let e = t.indirect_at_exits(exits, &ReferenceParams::with_spp(spp), &mut |_, _| {})?;
            Ok(Reference {
                mean: e.mean,
                variance: e.variance,
                seconds: 0.0,
            })
        })
    }

    /// An image of `mode` (indirect only, or direct only as mean with zero variance).
    #[allow(clippy::too_many_arguments)]
    pub fn image(
        &self,
        camera: &Camera,
        size: (u32, u32),
        light_spec: &str,
        light: &Light,
        spp: u32,
        direct_only: bool,
    ) -> Result<Reference> {
        let key = format!(
            "image{IMAGE_EPOCH}|{:?}|{:?}|{}|{size:?}|{light_spec}|{spp}|{direct_only}",
            camera.eye, camera.target, camera.fov_y_deg
        );
        self.cached(&key, || {
            let lights = [*light];
            let t = ReferenceTracer::new(self.scene, &self.bvh, Lighting::Lights(&lights));
            let (w, h) = size;
            if direct_only {
                // Full and indirect-only renders with the same seed draw the same paths, so their
                // difference is exactly the direct term; one path per pixel suffices.
                let one = ReferenceParams {
                    passes: 1,
                    samples_per_pass: 1,
                    ..ReferenceParams::STANDARD
                };
                let full = t.render(camera, w, h, ImageMode::Full, &one, &mut |_, _| {})?;
                let ind = t.render(camera, w, h, ImageMode::IndirectOnly, &one, &mut |_, _| {})?;
                let mean: Vec<Vec3> = full
                    .mean
                    .iter()
                    .zip(&ind.mean)
                    .map(|(a, b)| (*a - *b).max(Vec3::ZERO))
                    .collect();
                let n = mean.len();
                return Ok(Reference {
                    mean,
                    variance: vec![Vec3::ZERO; n],
                    seconds: 0.0,
                });
            }
            let e = t.render(
                camera,
                w,
                h,
                ImageMode::IndirectOnly,
                &ReferenceParams::with_spp(spp),
                &mut |_, _| {},
            )?;
            Ok(Reference {
                mean: e.mean,
                variance: e.variance,
                seconds: 0.0,
            })
        })
    }
}
