//! Reference path tracer: ground truth for indirect irradiance at exit points and for images.
//!
//! Indirect irradiance at `x` (receiving normal `n_x`) is `E_ind(x) = ∫ L(ω) cos θ dω` over the
//! hemisphere, where `L` is the radiance leaving the first surface `y₁` seen along `ω`:
//! `L = ρ(y₁)/π · (E_dir(y₁) + E_ind(y₁))`. Sampling `ω` with pdf `cos θ/π` gives the one-sample
//! estimate `π·L = ρ(y₁)·(E_dir(y₁) + E_ind(y₁))`, and recursing on `E_ind(y₁)` gives the path
//! estimator
//!
//! ```text
//! Ê_ind(x) = Σ_{j≥1} T_j · ρ(y_j) · E_dir(y_j),    T_1 = 1,  T_{j+1} = T_j · ρ(y_j) / q_j
//! ```
//!
//! with next-event estimation to the punctual lights for `E_dir(y_j)` ([`crate::direct_irradiance`])
//! and Russian roulette `q_j` ([`Roulette`]) after each vertex. Unbiased apart from the
//! `max_bounces` cap (tail below 2·10⁻⁶ by default). Surfaces are one-sided, as in the walks: a
//! ray hitting the back of a surface ends the path. Vertices use geometric normals; the exit point
//! uses its own (shading) normal for the first cosine, as the pane evaluator does, and so does a
//! pixel's first visible point (its direct light and its first indirect cosine), as the player
//! shades it. On the smooth-shaded fireplace room (the targets' lamp) the image with the
//! geometric normal there differs by 0.97% after the 4×4 downsample and 2.96% at full
//! resolution; on the flat-shaded Sponza and Cornell boxes by 0.10%.
//!
//! Images: one pinhole ray per pixel centre per pass (right-handed, +Y up, vertical FOV, row 0 at
//! the top). The radiance is `ρ(x)/π · (E_dir(x) + E_ind(x))` at the first visible point `x`, or
//! only `ρ(x)/π · E_ind(x)` with [`ImageMode::IndirectOnly`]; back faces and misses are black.
//! The first visible point is taken a spawn offset ([`Bvh::epsilon`]) back along the camera ray,
//! so a pixel centre that falls on the edge where two surfaces meet leaves from in front of both
//! (from the edge itself, the rays towards the second surface would slip past it: McGuire's box
//! at the targets' camera, square to its floor-wall edges, would show a diagonal of such pixels
//! at about 0.4 of the wall beside them, the largest local error of that image).
//!
//! Progressive: each pass adds `samples_per_pass` independent paths per texel/pixel; the pass
//! means are combined with Welford's algorithm, giving the mean and the variance of the mean
//! (`s²/passes`, zero until two passes exist). Texel `i` in pass `p` uses the stream
//! `(seed, i, p)`, so results do not depend on the thread count.
//!
//! [`Lighting::UniformIrradiance`] is a pseudo-light for the furnace test: every front-facing
//! surface point receives that direct irradiance, with no visibility.
//!
//! **Emissive surfaces** ([`ReferenceTracer::with_emitters`]) are area lights besides the
//! lighting: `E_dir(y_j)` gains one next-event sample of them at every path vertex
//! ([`Emitters::sample_weighted`] and [`Emitters::cosine_hit`], unbiased), and emission met along a path is not added
//! (the samples count it), so the estimator above stays the indirect irradiance. The direct
//! irradiance at exit points takes [`EMITTER_DIRECT_SAMPLES`] samples each (stream
//! `(0, exit, u64::MAX)`, fixed), and an image's full radiance adds the emission `L_e` of the
//! surface seen and a fresh sample of its direct light every pass.
//!
//! **The sky** ([`ReferenceTracer::with_sky`]) is radiance from every direction the scene leaves
//! open. A path ray from a vertex that leaves the scene along `ω` scores `π·L_sky(ω)` times its
//! weight: it is the cosine sample of that vertex's direct sky light, and the only one (there is
//! no next-event estimation of the sky, which suits smooth skies; a sun belongs in a
//! [`Light::Directional`]). The direct sky light at exit points takes [`SKY_DIRECT_SAMPLES`]
//! cosine samples (stream `(1, exit, u64::MAX)`), and an image's full radiance a fresh
//! `samples_per_pass` every pass. Camera rays that leave the scene stay black.

use glam::{Vec2, Vec3};
use prm_scene::{Camera, ExitPoint, Light, Scene};
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::direct::direct_irradiance;
use crate::emitters::{Emitters, Receiver};
use crate::rng::Rng;
use crate::sampling::cosine_hemisphere;
use crate::walk::Roulette;
use crate::TraceError;
use prm_scene::Sky;

/// Where direct light comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lighting<'a> {
    /// Punctual lights with shadows.
    Lights(&'a [Light]),
    /// Every front-facing surface point receives this irradiance (W/m²), no visibility (furnace).
    UniformIrradiance(Vec3),
}

/// What an image shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageMode {
    /// `ρ/π · (E_dir + E_ind)`.
    Full,
    /// `ρ/π · E_ind`.
    IndirectOnly,
}

/// Reference tracer parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceParams {
    /// Progressive passes.
    pub passes: u32,
    /// Paths per texel/pixel per pass.
    pub samples_per_pass: u32,
    /// Russian roulette after each vertex.
    pub roulette: Roulette,
    /// Hard cap on path vertices.
    pub max_bounces: u32,
    /// Seed.
    pub seed: u64,
}

impl ReferenceParams {
    /// 8 passes × 8 paths.
    pub const PREVIEW: ReferenceParams = ReferenceParams {
        passes: 8,
        samples_per_pass: 8,
        roulette: Roulette::DEFAULT,
        max_bounces: 256,
        seed: 0,
    };
    /// 16 passes × 64 paths.
    pub const STANDARD: ReferenceParams = ReferenceParams {
        passes: 16,
        samples_per_pass: 64,
        ..Self::PREVIEW
    };

    /// About `spp` paths in total, split into passes of at most 64 (at least 4 passes if possible).
    pub fn with_spp(spp: u32) -> Self {
        let spp = spp.max(1);
        let per = (spp / 4).clamp(1, 64);
        ReferenceParams {
            passes: spp.div_ceil(per),
            samples_per_pass: per,
            ..Self::STANDARD
        }
    }
}

impl Default for ReferenceParams {
    fn default() -> Self {
        Self::STANDARD
    }
}

/// A progressive estimate per texel or pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// Mean over passes.
    pub mean: Vec<Vec3>,
    /// Variance of the mean (sample variance of pass means / passes).
    pub variance: Vec<Vec3>,
    /// Passes done.
    pub passes: u32,
}

struct Welford {
    mean: Vec<Vec3>,
    m2: Vec<Vec3>,
    n: u32,
}

impl Welford {
    fn new(len: usize) -> Self {
        Welford {
            mean: vec![Vec3::ZERO; len],
            m2: vec![Vec3::ZERO; len],
            n: 0,
        }
    }
    fn add(&mut self, values: &[Vec3]) {
        self.n += 1;
        let n = self.n as f32;
        for ((m, s), &v) in self.mean.iter_mut().zip(self.m2.iter_mut()).zip(values) {
            let d = v - *m;
            *m += d / n;
            *s += d * (v - *m);
        }
    }
    fn estimate(&self) -> Estimate {
        let n = self.n as f32;
        let variance = if self.n > 1 {
            self.m2.iter().map(|s| *s / ((n - 1.0) * n)).collect()
        } else {
            vec![Vec3::ZERO; self.mean.len()]
        };
        Estimate {
            mean: self.mean.clone(),
            variance,
            passes: self.n,
        }
    }
}

/// Emitter samples per exit point in [`ReferenceTracer::direct_at_exits`]: about 6% noise
/// per texel where an emitter is seen at a grazing angle, far less once averaged over an image.
pub const EMITTER_DIRECT_SAMPLES: u32 = 256;

/// Cosine samples of the sky per exit point in [`ReferenceTracer::direct_at_exits`].
pub const SKY_DIRECT_SAMPLES: u32 = 256;

/// The reference path tracer over one scene and lighting.
pub struct ReferenceTracer<'a> {
    scene: &'a Scene,
    bvh: &'a Bvh,
    lighting: Lighting<'a>,
    emitters: Option<&'a Emitters>,
    sky: Option<&'a Sky>,
}

impl<'a> ReferenceTracer<'a> {
    /// A tracer for `scene` (with its `bvh`) under `lighting`.
    pub fn new(scene: &'a Scene, bvh: &'a Bvh, lighting: Lighting<'a>) -> Self {
        ReferenceTracer {
            scene,
            bvh,
            lighting,
            emitters: None,
            sky: None,
        }
    }

    /// The same tracer with `sky` lighting it besides the lighting (module docs).
    pub fn with_sky(self, sky: &'a Sky) -> Self {
        ReferenceTracer { sky: Some(sky), ..self }
    }

    /// The sky's direct irradiance at receiver `r`, `samples` cosine samples about `r.n` (zero
    /// without a sky): `π·L(ω)` for each ray `ω` that leaves the scene.
    pub(crate) fn sky_direct(&self, r: &Receiver, samples: u32, rng: &mut Rng) -> Vec3 {
        let Some(sky) = self.sky else {
            return Vec3::ZERO;
        };
        let (p, ng, n, tri) = (r.position, r.ng, r.n, r.triangle);
        let mut sum = Vec3::ZERO;
        for _ in 0..samples {
            let dir = cosine_hemisphere(rng.next_vec2(), n);
            if dir.dot(ng) > 0.0
                && !self
                    .bvh
                    .occluded(self.bvh.spawn(p, ng, dir), dir, f32::INFINITY, [tri, tri])
            {
                sum += sky.radiance(dir);
            }
        }
        sum * (std::f32::consts::PI / samples.max(1) as f32)
    }

    /// The same tracer with `emitters` as area lights besides the lighting (module docs).
    pub fn with_emitters(self, emitters: &'a Emitters) -> Self {
        ReferenceTracer {
            emitters: (!emitters.is_empty()).then_some(emitters),
            ..self
        }
    }

    /// The lighting's direct irradiance (deterministic).
    fn direct(&self, r: &Receiver) -> Vec3 {
        match self.lighting {
            Lighting::Lights(l) => direct_irradiance(self.bvh, l, r.position, r.ng, r.n, r.triangle),
            Lighting::UniformIrradiance(e) => e,
        }
    }

    /// The emitters' direct irradiance, `samples` next-event samples (zero without emitters).
    fn emitted(&self, r: &Receiver, samples: u32, rng: &mut Rng) -> Vec3 {
        self.emitters
            .map_or(Vec3::ZERO, |e| e.irradiance_at(self.scene, self.bvh, r, samples, rng))
    }

    /// `f(i, exit i as a receiver)` at every exit point, in parallel.
    fn at_exits(&self, exits: &[ExitPoint], f: impl Fn(usize, &Receiver) -> Vec3 + Sync) -> Vec<Vec3> {
        exits
            .par_iter()
            .enumerate()
            .map(|(i, x)| f(i, &Receiver::at_exit(self.bvh, x)))
            .collect()
    }

    /// Direct irradiance at every exit point (receiving with the exit point's normal): the
    /// lighting's, plus [`EMITTER_DIRECT_SAMPLES`] emitter samples with emitters and
    /// [`SKY_DIRECT_SAMPLES`] sky samples with a sky.
    pub fn direct_at_exits(&self, exits: &[ExitPoint]) -> Vec<Vec3> {
        self.at_exits(exits, |i, r| {
            let mut rng = Rng::new(0, i as u64, u64::MAX);
            let mut sky_rng = Rng::new(1, i as u64, u64::MAX);
            self.direct(r)
                + self.emitted(r, EMITTER_DIRECT_SAMPLES, &mut rng)
                + self.sky_direct(r, SKY_DIRECT_SAMPLES, &mut sky_rng)
        })
    }

    /// The sky's direct irradiance alone at every exit point, `samples` cosine samples each
    /// (stream `(1, exit, u64::MAX)`, as in [`ReferenceTracer::direct_at_exits`]; zero without
    /// a sky).
    pub fn sky_direct_at_exits(&self, exits: &[ExitPoint], samples: u32) -> Vec<Vec3> {
        self.at_exits(exits, |i, r| {
            self.sky_direct(r, samples, &mut Rng::new(1, i as u64, u64::MAX))
        })
    }

    /// The sky's direct irradiance alone at points of empty space, each `(position, unit
    /// normal)` on no triangle (a probe's), `samples` cosine samples each (stream
    /// `(1, point, u64::MAX)`; zero without a sky).
    pub fn sky_direct_at_points(&self, points: &[(Vec3, Vec3)], samples: u32) -> Vec<Vec3> {
        points
            .par_iter()
            .enumerate()
            .map(|(i, &(x, n))| {
                let r = Receiver {
                    position: x,
                    ng: n,
                    n,
                    triangle: u32::MAX,
                };
                self.sky_direct(&r, samples, &mut Rng::new(1, i as u64, u64::MAX))
            })
            .collect()
    }

    /// One path estimate of the indirect irradiance at `x`.
    fn indirect_path(&self, x: Vec3, ng: Vec3, n: Vec3, tri: u32, p: &ReferenceParams, rng: &mut Rng) -> Vec3 {
        let mut sum = Vec3::ZERO;
        walk_path(
            self.scene,
            self.bvh,
            (x, ng, n, tri),
            None,
            p,
            rng,
            &mut |step, rng| match step {
                Step::Vertex(v) => {
                    // The segment from a vertex (not from x: light straight from an emitter to x is
                    // direct light there) is also the cosine half of that vertex's emitter estimate;
                    // it was traced with probability q, which `throughput` already divides by.
                    if let (Some(e), true) = (self.emitters, v.bounce > 0) {
                        sum += v.throughput * e.cosine_hit(self.scene, self.bvh, v.hit, v.dir, v.cos_from);
                    }
                    let r = Receiver {
                        position: v.pos,
                        ng: v.ng,
                        n: v.ng,
                        triangle: v.tri,
                    };
                    let emitted = self
                        .emitters
                        .map_or(Vec3::ZERO, |e| e.sample_weighted(self.scene, self.bvh, &r, rng));
                    sum += v.throughput * v.rho * (self.direct(&r) + emitted);
                }
                // Likewise the sky seen from a vertex is that vertex's direct sky light, sampled by
                // the cosine; from x it is x's own direct light.
                Step::Escape {
                    bounce,
                    throughput,
                    dir,
                } => {
                    if let (Some(sky), true) = (self.sky, bounce > 0) {
                        sum += throughput * std::f32::consts::PI * sky.radiance(dir);
                    }
                }
            },
        );
        sum
    }

    /// Mean of `samples_per_pass` path estimates of the indirect irradiance at `x`.
    fn indirect_mean(&self, x: Vec3, ng: Vec3, n: Vec3, tri: u32, p: &ReferenceParams, rng: &mut Rng) -> Vec3 {
        let mut s = Vec3::ZERO;
        for _ in 0..p.samples_per_pass {
            s += self.indirect_path(x, ng, n, tri, p, rng);
        }
        s / p.samples_per_pass as f32
    }

    /// Indirect irradiance (W/m²) at every exit point, progressively.
    /// `progress(pass, passes)` is called after every pass.
    pub fn indirect_at_exits(
        &self,
        exits: &[ExitPoint],
        params: &ReferenceParams,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<Estimate, TraceError> {
        validate(params)?;
        Ok(progressive(exits.len(), params, progress, |i, rng| {
            let x = &exits[i];
            let ng = self.bvh.geometric_normal(x.triangle);
            self.indirect_mean(x.position, ng, x.normal, x.triangle, params, rng)
        }))
    }

    /// Indirect irradiance (W/m²) at points of empty space, each `(position, unit normal)` a
    /// surface element on no triangle (a probe's), progressively; the light reaching it
    /// straight from a light, an emitter or the sky is direct and not counted.
    pub fn indirect_at_points(
        &self,
        points: &[(Vec3, Vec3)],
        params: &ReferenceParams,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<Estimate, TraceError> {
        validate(params)?;
        Ok(progressive(points.len(), params, progress, |i, rng| {
            let (x, n) = points[i];
            self.indirect_mean(x, n, n, u32::MAX, params, rng)
        }))
    }

    /// Radiance image (W/(m²·sr)) seen by `camera`, `width × height`, row-major from the top row.
    pub fn render(
        &self,
        camera: &Camera,
        width: u32,
        height: u32,
        mode: ImageMode,
        params: &ReferenceParams,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<Estimate, TraceError> {
        validate(params)?;
        if width == 0 || height == 0 {
            return Err(TraceError::InvalidParameter("image size must be positive".into()));
        }
        let forward = (camera.target - camera.eye).normalize_or_zero();
        if forward == Vec3::ZERO || !camera.is_valid() {
            return Err(TraceError::InvalidParameter(format!(
                "degenerate camera: eye {} looking at {}, vertical field of view {}° (the eye and \
                 the target must differ and the field of view lie in (0°, 180°))",
                camera.eye, camera.target, camera.fov_y_deg
            )));
        }
        let mut right = forward.cross(Vec3::Y);
        if right.length_squared() < 1e-12 {
            right = forward.cross(Vec3::Z);
        }
        let right = right.normalize();
        let up = right.cross(forward);
        let tan = (camera.fov_y_deg.to_radians() * 0.5).tan();
        let aspect = width as f32 / height as f32;
        // First hits are the same every pass: find them once (with the lighting's direct light
        // and the emission seen; the emitters' direct light is sampled every pass).
        let primary: Vec<Option<Primary>> = (0..width * height)
            .into_par_iter()
            .map(|i| {
                let (px, py) = (i % width, i / width);
                let s = Vec2::new(
                    (2.0 * (px as f32 + 0.5) / width as f32 - 1.0) * tan * aspect,
                    (1.0 - 2.0 * (py as f32 + 0.5) / height as f32) * tan,
                );
                let dir = (forward + right * s.x + up * s.y).normalize();
                let hit = self.bvh.closest_hit(camera.eye, dir, f32::INFINITY, u32::MAX)?;
                if !hit.front {
                    return None;
                }
                // Stepped back towards the eye by the spawn offset: a pixel centre on the edge
                // where two surfaces meet (a camera square to a box's floor-wall edge puts a row
                // of them there) would otherwise lie on the second surface's plane too, and the
                // rays leaving towards it would slip past its edge and escape (that row played
                // at 0.71 of the emissive furnace's radiance). Backed off along the ray, the
                // point is in front of every surface the eye sees there.
                let p = self.scene.triangles[hit.triangle as usize].point(hit.b1, hit.b2) - dir * self.bvh.epsilon();
                let ng = self.bvh.geometric_normal(hit.triangle);
                let ns = self.scene.triangles[hit.triangle as usize].shading_normal(hit.b1, hit.b2);
                let rho = self.scene.albedo(hit.triangle as usize, hit.b1, hit.b2);
                let receiver = Receiver {
                    position: p,
                    ng,
                    n: ns,
                    triangle: hit.triangle,
                };
                let (direct, emission) = match mode {
                    ImageMode::Full => (
                        self.direct(&receiver),
                        self.emitters.map_or(Vec3::ZERO, |e| e.emission(hit.triangle)),
                    ),
                    ImageMode::IndirectOnly => (Vec3::ZERO, Vec3::ZERO),
                };
                Some(Primary {
                    p,
                    ns,
                    tri: hit.triangle,
                    rho,
                    direct,
                    emission,
                })
            })
            .collect();
        Ok(progressive(primary.len(), params, progress, |i, rng| {
            let Some(Primary {
                p,
                ns,
                tri,
                rho,
                direct,
                emission,
            }) = primary[i]
            else {
                return Vec3::ZERO;
            };
            let r = Receiver {
                position: p,
                ng: self.bvh.geometric_normal(tri),
                n: ns,
                triangle: tri,
            };
            let emitted = match mode {
                ImageMode::Full => {
                    self.emitted(&r, params.samples_per_pass, rng) + self.sky_direct(&r, params.samples_per_pass, rng)
                }
                ImageMode::IndirectOnly => Vec3::ZERO,
            };
            emission
                + rho
                    * std::f32::consts::FRAC_1_PI
                    * (direct + emitted + self.indirect_mean(p, r.ng, ns, tri, params, rng))
        }))
    }
}

/// One event of a path: it met a surface, or left the scene.
pub(crate) enum Step<'h> {
    /// The path's ray `bounce` (0: the one leaving x) met the front of a surface.
    Vertex(&'h Vertex<'h>),
    /// Ray `bounce`, sampled with weight `throughput`, left the scene along `dir`.
    Escape {
        /// Which ray (0: from x).
        bounce: u32,
        /// The path weight the ray was traced with.
        throughput: Vec3,
        /// Its unit direction.
        dir: Vec3,
    },
}

/// A surface vertex of a path.
pub(crate) struct Vertex<'h> {
    pub bounce: u32,
    /// The path weight before this vertex's albedo.
    pub throughput: Vec3,
    pub hit: &'h crate::Hit,
    /// The ray's direction and its cosine at the vertex it left.
    pub dir: Vec3,
    pub cos_from: f32,
    pub pos: Vec3,
    /// Geometric normal (vertices shade with it).
    pub ng: Vec3,
    pub tri: u32,
    pub rho: Vec3,
}

/// Follows one cosine-sampled path from `start = (x, ng, n, triangle)` (the first cosine about
/// the shading normal `n`, from `first` if given, else from `rng`; later ones about geometric
/// normals), with Russian roulette after each vertex and at most `max_bounces` rays, calling
/// `visit` at every event. A ray below the geometric surface or meeting a back face ends the
/// path without an event.
pub(crate) fn walk_path(
    scene: &Scene,
    bvh: &Bvh,
    start: (Vec3, Vec3, Vec3, u32),
    first: Option<Vec2>,
    p: &ReferenceParams,
    rng: &mut Rng,
    visit: &mut dyn FnMut(Step, &mut Rng),
) {
    let (mut pos, mut ng, mut n, mut tri) = start;
    let mut throughput = Vec3::ONE;
    for bounce in 0..p.max_bounces {
        let u = match first {
            Some(u) if bounce == 0 => u,
            _ => rng.next_vec2(),
        };
        let dir = cosine_hemisphere(u, n);
        if dir.dot(ng) <= 0.0 {
            return;
        }
        let Some(hit) = bvh.closest_hit(bvh.spawn(pos, ng, dir), dir, f32::INFINITY, tri) else {
            visit(
                Step::Escape {
                    bounce,
                    throughput,
                    dir,
                },
                rng,
            );
            return;
        };
        if !hit.front {
            return;
        }
        let cos_from = n.dot(dir);
        tri = hit.triangle;
        pos = scene.triangles[tri as usize].point(hit.b1, hit.b2);
        ng = bvh.geometric_normal(tri);
        n = ng;
        let rho = scene.albedo(tri as usize, hit.b1, hit.b2);
        let v = Vertex {
            bounce,
            throughput,
            hit: &hit,
            dir,
            cos_from,
            pos,
            ng,
            tri,
            rho,
        };
        visit(Step::Vertex(&v), rng);
        let q = p.roulette.survival(rho);
        if rng.next_f32() >= q {
            return;
        }
        throughput *= rho / q;
    }
}

/// A pixel's first visible point: position, triangle, albedo, the lighting's direct irradiance
/// and the radiance it emits (both zero for indirect-only images).
#[derive(Clone, Copy)]
struct Primary {
    p: Vec3,
    /// The shading normal at the visible point (the first cosine's, as at exit points).
    ns: Vec3,
    tri: u32,
    rho: Vec3,
    direct: Vec3,
    emission: Vec3,
}

/// Runs the passes over `len` texels or pixels: `sample(i, rng)` is one pass's value at `i`,
/// drawn from the stream `(seed, i, pass)`; `progress(pass, passes)` is called after every pass.
fn progressive(
    len: usize,
    params: &ReferenceParams,
    progress: &mut dyn FnMut(u32, u32),
    sample: impl Fn(usize, &mut Rng) -> Vec3 + Sync,
) -> Estimate {
    let mut w = Welford::new(len);
    for pass in 0..params.passes {
        let values: Vec<Vec3> = (0..len)
            .into_par_iter()
            .map(|i| sample(i, &mut Rng::new(params.seed, i as u64, pass as u64)))
            .collect();
        w.add(&values);
        progress(pass + 1, params.passes);
    }
    w.estimate()
}

pub(crate) fn validate(p: &ReferenceParams) -> Result<(), TraceError> {
    if p.passes == 0 || p.samples_per_pass == 0 {
        return Err(TraceError::InvalidParameter(
            "passes and samples per pass must be positive".into(),
        ));
    }
    if !(p.roulette.min > 0.0 && p.roulette.min <= p.roulette.max && p.roulette.max <= 1.0) {
        return Err(TraceError::InvalidParameter(
            "roulette bounds must satisfy 0 < min <= max <= 1".into(),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welford_matches_direct_formulas() {
        let mut w = Welford::new(1);
        let xs = [1.0f32, 2.0, 4.0, 7.0];
        for x in xs {
            w.add(&[Vec3::splat(x)]);
        }
        let e = w.estimate();
        let mean = xs.iter().sum::<f32>() / 4.0;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / 3.0;
        assert!((e.mean[0].x - mean).abs() < 1e-6);
        assert!((e.variance[0].x - var / 4.0).abs() < 1e-5);
    }

    #[test]
    fn spp_split() {
        let p = ReferenceParams::with_spp(256);
        assert_eq!(p.passes * p.samples_per_pass, 256);
        assert!(p.passes >= 4);
        let p = ReferenceParams::with_spp(3);
        assert!(p.passes * p.samples_per_pass >= 3);
    }
}
