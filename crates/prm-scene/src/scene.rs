//! The flat scene: triangles with per-corner attributes, materials, lights, cameras.

use glam::{Vec2, Vec3};
use std::path::PathBuf;

use crate::texture::Texture;

/// One triangle in world space with its per-corner attributes.
#[derive(Clone, Debug, PartialEq)]
pub struct Triangle {
    /// Corner positions.
    pub positions: [Vec3; 3],
    /// Corner shading normals (unit length, on the side of the geometric normal).
    pub normals: [Vec3; 3],
    /// Corner material texture coordinates (zero when the file has none).
    pub uvs: [Vec2; 3],
    /// Index into [`Scene::materials`].
    pub material: u32,
}

impl Triangle {
    /// A flat triangle: its geometric normal at every corner, no texture coordinates.
    pub fn flat(positions: [Vec3; 3], material: u32) -> Triangle {
        let n = (positions[1] - positions[0])
            .cross(positions[2] - positions[0])
            .normalize_or_zero();
        Triangle {
            positions,
            normals: [n; 3],
            uvs: [Vec2::ZERO; 3],
            material,
        }
    }

    /// Unnormalised geometric normal, `(p1 - p0) × (p2 - p0)`; its length is twice the area.
    pub fn cross(&self) -> Vec3 {
        (self.positions[1] - self.positions[0]).cross(self.positions[2] - self.positions[0])
    }

    /// Area in square scene units.
    pub fn area(&self) -> f32 {
        0.5 * self.cross().length()
    }

    /// Unit geometric normal (counter-clockwise winding).
    pub fn normal(&self) -> Vec3 {
        self.cross().normalize_or_zero()
    }

    /// Position at barycentric coordinates `(b1, b2)` (weights of corners 1 and 2).
    pub fn point(&self, b1: f32, b2: f32) -> Vec3 {
        let p = &self.positions;
        p[0] * (1.0 - b1 - b2) + p[1] * b1 + p[2] * b2
    }

    /// Interpolated shading normal at barycentric `(b1, b2)`, unit length.
    pub fn shading_normal(&self, b1: f32, b2: f32) -> Vec3 {
        let n = &self.normals;
        let s = (n[0] * (1.0 - b1 - b2) + n[1] * b1 + n[2] * b2).normalize_or_zero();
        if s == Vec3::ZERO {
            self.normal()
        } else {
            s
        }
    }

    /// Interpolated material texture coordinate at barycentric `(b1, b2)`.
    pub fn uv(&self, b1: f32, b2: f32) -> Vec2 {
        let t = &self.uvs;
        t[0] * (1.0 - b1 - b2) + t[1] * b1 + t[2] * b2
    }
}

/// A diffuse material.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name from the file (or a generated one).
    pub name: String,
    /// Linear RGB diffuse albedo; multiplies the texture when there is one.
    pub albedo: Vec3,
    /// Index into [`Scene::textures`] of the base colour texture (sRGB-encoded).
    pub texture: Option<u32>,
    /// Emitted radiance, W/(m²·sr) per linear RGB channel, uniform over the surface and the
    /// hemisphere (Lambertian emission); zero for a surface that only reflects. From OBJ `Ke`,
    /// and glTF `emissiveFactor` × `KHR_materials_emissive_strength`.
    pub emission: Vec3,
}

/// A punctual light. Units follow `prm-bake reference --light`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// Point light: radiant intensity in W/sr per channel.
    Point {
        /// Position.
        position: Vec3,
        /// Radiant intensity (W/sr) per RGB channel.
        intensity: Vec3,
    },
    /// Spot light: a point light restricted to a cone around `direction`.
    Spot {
        /// Position.
        position: Vec3,
        /// Unit axis of the cone.
        direction: Vec3,
        /// Half angle of the cone, radians.
        angle: f32,
        /// Radiant intensity (W/sr) per RGB channel inside the cone.
        intensity: Vec3,
    },
    /// Rectangular spot light (the paper's projector): a point light restricted to a
    /// rectangular frustum around `direction`, hard-edged like [`Light::Spot`].
    Rect {
        /// Position.
        position: Vec3,
        /// Unit axis of the frustum.
        direction: Vec3,
        /// Unit vector perpendicular to `direction`: the frustum's vertical. Its horizontal is
        /// `direction × up`.
        up: Vec3,
        /// Half angles of the frustum, radians: horizontal (along `direction × up`) and
        /// vertical (along `up`), each in (0, 85°).
        half_angles: [f32; 2],
        /// Radiant intensity (W/sr) per RGB channel inside the frustum.
        intensity: Vec3,
    },
    /// Directional light travelling along `direction`.
    Directional {
        /// Unit direction the light travels in.
        direction: Vec3,
        /// Irradiance (W/m²) on a surface facing the light, per channel.
        irradiance: Vec3,
    },
}

/// Largest half angle of a [`Light::Rect`], degrees: its shadow map is one perspective view,
/// which must stay well short of 90° (at 85° a texel at the rim is 130 times one at the axis).
pub const RECT_MAX_HALF_ANGLE_DEG: f32 = 85.0;

impl Light {
    /// The position of a point, spot or rectangular spot light (None for a directional one).
    pub fn position_mut(&mut self) -> Option<&mut Vec3> {
        match self {
            Light::Point { position, .. } | Light::Spot { position, .. } | Light::Rect { position, .. } => {
                Some(position)
            }
            Light::Directional { .. } => None,
        }
    }

    /// Whether the light emits along the unit direction `from_light` (from the light towards
    /// a point): always for point and directional lights, inside the cone of a spot and inside
    /// the frustum of a rectangular spot (boundaries included). The run-time twin is the cone
    /// and frustum test of `light_irradiance_ng` in `shaders/runtime/lights.wgsl`.
    pub fn emits_towards(&self, from_light: Vec3) -> bool {
        match *self {
            Light::Point { .. } | Light::Directional { .. } => true,
            Light::Spot { direction, angle, .. } => from_light.dot(direction) >= angle.cos(),
            Light::Rect {
                direction,
                up,
                half_angles,
                ..
            } => {
                let z = from_light.dot(direction);
                let x = from_light.dot(direction.cross(up));
                let y = from_light.dot(up);
                z > 0.0 && x.abs() <= z * half_angles[0].tan() && y.abs() <= z * half_angles[1].tan()
            }
        }
    }
}

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub eye: Vec3,
    /// A point the camera looks at.
    pub target: Vec3,
    /// Vertical field of view, degrees.
    pub fov_y_deg: f32,
}

impl Camera {
    /// Whether it can render: finite, the eye apart from the target, and a vertical field of
    /// view in (0°, 180°) (what `--camera` accepts).
    pub fn is_valid(&self) -> bool {
        self.eye.is_finite()
            && self.target.is_finite()
            && self.eye != self.target
            && self.fov_y_deg > 0.0
            && self.fov_y_deg < 180.0
    }
}

/// Axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Minimum corner.
    pub min: Vec3,
    /// Maximum corner.
    pub max: Vec3,
}

impl Aabb {
    /// The empty box (min = +∞, max = −∞).
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };

    /// Grows the box to contain `p`.
    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// Edge lengths.
    pub fn extent(&self) -> Vec3 {
        (self.max - self.min).max(Vec3::ZERO)
    }

    /// Length of the diagonal.
    pub fn diagonal(&self) -> f32 {
        self.extent().length()
    }
}

/// What the loader passed over without failing: warnings to show the user.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LoadReport {
    /// Human-readable warnings (missing MTL or texture, unsupported primitives, ...).
    pub warnings: Vec<String>,
    /// Triangles dropped because their area was zero (or negligible).
    pub degenerate_dropped: usize,
    /// Triangles dropped because an earlier one has the same corners in the same winding (a
    /// face listed twice, as McGuire's Cornell boxes list two of their blocks' faces): the second
    /// copy hides nothing from a ray, but it doubles the face's share of area-sampled points, and
    /// a ray leaving the face from its surface meets the copy at once.
    pub duplicates_dropped: usize,
    /// Triangles with a corner beyond ±[`MAX_COORDINATE`]; the load fails when there is one.
    pub out_of_range: usize,
}

/// Largest vertex coordinate, in scene units (metres), that a scene may have. At 10⁹ the
/// 32-bit positions the bake and the player work in are 64 units apart, so no surface detail
/// survives; and the bake's sums over areas and squared distances overflow at about 10¹⁸
/// (a scene at 10¹⁸ would fail in the near field with an infinite disk, one at 10³⁰ lose every
/// triangle as degenerate). Real scenes stay within 10⁵ or so.
pub const MAX_COORDINATE: f32 = 1e9;

/// A loaded scene, flat and in world space.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The file it came from.
    pub source: PathBuf,
    /// All triangles.
    pub triangles: Vec<Triangle>,
    /// Lightmap UVs from the file (glTF `TEXCOORD_1`), one per corner, for every triangle.
    pub lightmap_uvs: Option<Vec<[Vec2; 3]>>,
    /// Materials referenced by [`Triangle::material`].
    pub materials: Vec<Material>,
    /// Textures referenced by [`Material::texture`].
    pub textures: Vec<Texture>,
    /// Lights from the file.
    pub lights: Vec<Light>,
    /// Cameras from the file.
    pub cameras: Vec<Camera>,
    /// What the loader passed over.
    pub report: LoadReport,
}

impl Material {
    /// A diffuse material without texture or emission.
    pub fn diffuse(name: &str, albedo: Vec3) -> Material {
        Material {
            name: name.to_string(),
            albedo,
            texture: None,
            emission: Vec3::ZERO,
        }
    }
}

impl Scene {
    /// A scene of these triangles and materials alone: no lights, cameras, textures or lightmap
    /// UVs (tests and generated scenes).
    pub fn from_parts(triangles: Vec<Triangle>, materials: Vec<Material>) -> Scene {
        Scene {
            source: PathBuf::from("parts"),
            triangles,
            lightmap_uvs: None,
            materials,
            textures: Vec::new(),
            lights: Vec::new(),
            cameras: Vec::new(),
            report: LoadReport::default(),
        }
    }

    /// Bounds of all triangle corners.
    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for t in &self.triangles {
            for p in t.positions {
                b.grow(p);
            }
        }
        b
    }

    /// Names of the materials that emit ([`Material::emission`] not zero), in order.
    pub fn emissive_materials(&self) -> Vec<&str> {
        self.materials
            .iter()
            .filter(|m| m.emission.max_element() > 0.0)
            .map(|m| m.name.as_str())
            .collect()
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        self.triangles.iter().map(|t| t.area() as f64).sum()
    }

    /// Radius² of the disk each of `entries` uniformly sampled entry points stands for in the
    /// run time's bound on its irradiance: [`crate::ENTRY_DISK`] × A/(Nπ).
    pub fn entry_disk(&self, entries: usize) -> f32 {
        crate::ENTRY_DISK * (self.area() / entries.max(1) as f64 / std::f64::consts::PI) as f32
    }

    /// Diffuse albedo of triangle `tri` at barycentric `(b1, b2)`: material albedo times texture.
    pub fn albedo(&self, tri: usize, b1: f32, b2: f32) -> Vec3 {
        let t = &self.triangles[tri];
        let m = &self.materials[t.material as usize];
        match m.texture {
            Some(i) => m.albedo * self.textures[i as usize].sample(t.uv(b1, b2)),
            None => m.albedo,
        }
    }

    /// A stable 64-bit fingerprint of the geometry: triangle count and every corner position's
    /// bits, in order (xxh3). Materials, lights and cameras do not enter it, so an archive stays
    /// valid when only those change.
    ///
    /// A **geometry mismatch means refuse**: an archive whose recorded fingerprint differs from
    /// the scene's was baked for other geometry and must not be played. Albedo changes are
    /// caught by [`Scene::materials_fingerprint`] instead, which only warrants a warning.
    pub fn fingerprint(&self) -> u64 {
        let mut h = xxhash_rust::xxh3::Xxh3::new();
        h.update(&(self.triangles.len() as u64).to_le_bytes());
        for t in &self.triangles {
            for p in t.positions {
                for c in p.to_array() {
                    h.update(&c.to_bits().to_le_bytes());
                }
            }
        }
        h.digest()
    }

    /// A stable 64-bit fingerprint of what the baked panes depend on besides geometry: for every
    /// triangle, in order, its material's albedo bits and, when textured, the texture's size and
    /// texels plus the triangle's material UVs (xxh3). Material names, lights and cameras do not
    /// enter it; neither does the material table's order, only what each triangle ends up with.
    ///
    /// A **materials mismatch means warn**: the archive's indirect light was computed with other
    /// albedos, so it is still usable but no longer exact. A geometry mismatch
    /// ([`Scene::fingerprint`]) means refuse.
    pub fn materials_fingerprint(&self) -> u64 {
        // Each texture is hashed once; triangles then refer to its digest.
        let texture_digests: Vec<u64> = self
            .textures
            .iter()
            .map(|t| {
                let mut h = xxhash_rust::xxh3::Xxh3::new();
                h.update(&t.width.to_le_bytes());
                h.update(&t.height.to_le_bytes());
                for texel in &t.texels {
                    h.update(texel);
                }
                h.digest()
            })
            .collect();
        let mut h = xxhash_rust::xxh3::Xxh3::new();
        h.update(&(self.triangles.len() as u64).to_le_bytes());
        for t in &self.triangles {
            let Some(m) = self.materials.get(t.material as usize) else {
                h.update(&[0xff]);
                continue;
            };
            for c in m.albedo.to_array() {
                h.update(&c.to_bits().to_le_bytes());
            }
            match m.texture.and_then(|i| texture_digests.get(i as usize)) {
                Some(d) => {
                    h.update(&[1]);
                    h.update(&d.to_le_bytes());
                    for uv in t.uvs {
                        for c in uv.to_array() {
                            h.update(&c.to_bits().to_le_bytes());
                        }
                    }
                }
                None => h.update(&[0]),
            }
        }
        h.digest()
    }

    /// Ends a loader's work: drops duplicate triangles, warns of the dropped degenerate and
    /// duplicate triangles, and fails when none is left.
    pub(crate) fn finish_load(mut self) -> Result<Scene, crate::SceneError> {
        if self.report.out_of_range > 0 {
            return Err(crate::SceneError::Malformed {
                path: self.source.clone(),
                line: None,
                message: format!(
                    "{} triangles have a corner beyond ±{MAX_COORDINATE:e} units, where 32-bit \
                     positions keep no detail (scale the scene to metres)",
                    self.report.out_of_range
                ),
            });
        }
        self.sanitize_materials();
        self.sanitize_lights_and_cameras();
        let n = self.report.degenerate_dropped;
        if n > 0 {
            self.report
                .warnings
                .push(format!("{}: {n} degenerate triangles dropped", self.source.display()));
        }
        let keep = first_copies(&self.triangles);
        let duplicates = keep.iter().filter(|k| !**k).count();
        if duplicates > 0 {
            let mut flags = keep.iter();
            self.triangles.retain(|_| *flags.next().unwrap_or(&true));
            if let Some(uvs) = &mut self.lightmap_uvs {
                let mut flags = keep.iter();
                uvs.retain(|_| *flags.next().unwrap_or(&true));
            }
            self.report.duplicates_dropped = duplicates;
            self.report.warnings.push(format!(
                "{}: {duplicates} duplicate triangles dropped (the same corners, in the same winding, as an earlier triangle)",
                self.source.display()
            ));
        }
        if self.triangles.is_empty() {
            return Err(crate::SceneError::NoTriangles {
                path: self.source.clone(),
                dropped: n,
            });
        }
        Ok(self)
    }

    /// Albedos must lie in [0, 1] (a diffuse surface reflects at most what it receives: above
    /// 1 the walks gain energy at every bounce) and emission must be finite and non-negative;
    /// others are clamped (NaN to 0), with a warning naming the material.
    fn sanitize_materials(&mut self) {
        for m in &mut self.materials {
            let a = m.albedo;
            if !(a.is_finite() && a.min_element() >= 0.0 && a.max_element() <= 1.0) {
                let clamped = Vec3::from_array(a.to_array().map(|c| if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) }));
                self.report.warnings.push(format!(
                    "{}: material '{}' has albedo {a} outside [0, 1]; using {clamped}",
                    self.source.display(),
                    m.name
                ));
                m.albedo = clamped;
            }
            let e = m.emission;
            if !(e.is_finite() && e.min_element() >= 0.0) {
                self.report.warnings.push(format!(
                    "{}: material '{}' has emission {e} (negative or not finite); it does not emit",
                    self.source.display(),
                    m.name
                ));
                m.emission = Vec3::ZERO;
            }
        }
    }

    /// Drops, with a warning, lights whose intensity is negative or not finite, or whose cone
    /// or frustum is empty, and cameras with no field of view: the player and the reference
    /// would show them as a black image.
    fn sanitize_lights_and_cameras(&mut self) {
        let source = self.source.display().to_string();
        let mut warnings = Vec::new();
        self.lights.retain(|l| {
            let (power, shape_ok) = match *l {
                Light::Point { intensity, .. } => (intensity, true),
                Light::Spot { angle, intensity, .. } => (intensity, angle.is_finite() && angle > 0.0),
                Light::Rect {
                    half_angles, intensity, ..
                } => (intensity, half_angles.iter().all(|a| a.is_finite() && *a > 0.0)),
                Light::Directional { irradiance, .. } => (irradiance, true),
            };
            let power_ok = power.is_finite() && power.min_element() >= 0.0;
            if !(shape_ok && power_ok) {
                let (kind, at) = match *l {
                    Light::Point { position, .. } => ("point light", format!(" at {position}")),
                    Light::Spot { position, .. } => ("spot light", format!(" at {position}")),
                    Light::Rect { position, .. } => ("rectangular spot light", format!(" at {position}")),
                    Light::Directional { direction, .. } => ("directional light", format!(" along {direction}")),
                };
                let why = if power_ok {
                    "its cone is empty".to_string()
                } else {
                    format!("its intensity {power} is negative or not finite")
                };
                warnings.push(format!("{source}: the {kind}{at} is left out: {why}"));
            }
            shape_ok && power_ok
        });
        self.cameras.retain(|c| {
            let ok = c.is_valid();
            if !ok {
                warnings.push(format!(
                    "{source}: a camera with field of view {}° at {} looking at {} is left out",
                    c.fov_y_deg, c.eye, c.target
                ));
            }
            ok
        });
        self.report.warnings.extend(warnings);
    }

    /// Appends a triangle after validating it; returns false (and counts it) when degenerate.
    ///
    /// `area_eps` is the area below which a triangle counts as degenerate. Corner normals that are
    /// missing (zero) or point away from the geometric normal are replaced or flipped.
    pub(crate) fn push_triangle(&mut self, mut t: Triangle, area_eps: f32) -> bool {
        if t.positions
            .iter()
            .any(|p| p.is_finite() && p.abs().max_element() > MAX_COORDINATE)
        {
            self.report.out_of_range += 1;
            return false;
        }
        let area = t.area();
        if area.is_nan() || area <= area_eps {
            self.report.degenerate_dropped += 1;
            return false;
        }
        let ng = t.normal();
        for n in &mut t.normals {
            let u = n.normalize_or_zero();
            *n = if u == Vec3::ZERO || !u.is_finite() || u.dot(ng).abs() < 0.05 {
                // Missing, or (nearly) in the face's plane: the face's own normal is safer.
                ng
            } else if u.dot(ng) < 0.0 {
                // Shading normals on the far side of the face: the file's winding and normals
                // disagree. Keep the geometry's winding and mirror the normal.
                -u
            } else {
                u
            };
        }
        self.triangles.push(t);
        true
    }
}

/// For every triangle, whether it is the first with its corners in its winding (the same three
/// positions, bit for bit, in the same cyclic order).
fn first_copies(triangles: &[Triangle]) -> Vec<bool> {
    let mut seen = std::collections::HashSet::with_capacity(triangles.len());
    triangles
        .iter()
        .map(|t| {
            let bits = t.positions.map(|p| p.to_array().map(f32::to_bits));
            let first = (0..3).min_by_key(|&i| bits[i]).unwrap_or(0);
            let key = [bits[first], bits[(first + 1) % 3], bits[(first + 2) % 3]];
            seen.insert(key)
        })
        .collect()
}

/// Degenerate-area threshold for a scene whose bounding-box diagonal is `diag`.
pub(crate) fn area_epsilon(diag: f32) -> f32 {
    (diag * diag * 1e-14).max(f32::MIN_POSITIVE)
}
