//! Scene description shared by the generators and writers: parts made of planar polygons.

/// A point or vector in metres (right-handed, +Y up).
pub type V3 = [f64; 3];

pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn length(a: V3) -> f64 {
    dot(a, a).sqrt()
}

pub fn normalize(a: V3) -> V3 {
    scale(a, 1.0 / length(a))
}

/// Newell normal of a polygon (length = twice its area for a planar polygon).
pub fn newell(poly: &[V3]) -> V3 {
    let mut n = [0.0; 3];
    for (i, a) in poly.iter().enumerate() {
        let b = poly[(i + 1) % poly.len()];
        n[0] += (a[1] - b[1]) * (a[2] + b[2]);
        n[1] += (a[2] - b[2]) * (a[0] + b[0]);
        n[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    n
}

/// Whether all vertices lie within 0.1 µm of the polygon's plane.
pub fn is_planar(poly: &[V3]) -> bool {
    if poly.len() == 3 {
        return true;
    }
    let n = normalize(newell(poly));
    poly.iter().all(|p| dot(sub(*p, poly[0]), n).abs() <= 1e-7)
}

/// A named, single-material piece of a scene: convex planar polygons (triangles or quads),
/// counter-clockwise seen from the side they face.
pub struct Part {
    pub name: String,
    pub material: String,
    pub polys: Vec<Vec<V3>>,
}

impl Part {
    pub fn new(name: impl Into<String>, material: &str, polys: Vec<Vec<V3>>) -> Part {
        Part {
            name: name.into(),
            material: material.into(),
            polys,
        }
    }
}

/// A Lambertian material: linear-RGB albedo, optional emission (MTL `Ke`; glTF
/// `emissiveFactor` × `KHR_materials_emissive_strength`).
pub struct Material {
    pub name: String,
    pub albedo: [f64; 3],
    pub emission: Option<[f64; 3]>,
}

impl Material {
    /// A material that does not emit.
    pub fn diffuse(name: &str, albedo: [f64; 3]) -> Material {
        Material {
            name: name.into(),
            albedo,
            emission: None,
        }
    }
}

/// A pinhole camera: eye, target, vertical field of view in degrees.
pub struct CameraSpec {
    pub eye: V3,
    pub target: V3,
    pub fov_y_deg: f64,
    /// Width / height, when the source fixes it (written as glTF `aspectRatio`).
    pub aspect: Option<f64>,
}

impl CameraSpec {
    /// A camera whose aspect ratio the renderer chooses.
    pub const fn free_aspect(eye: V3, target: V3, fov_y_deg: f64) -> CameraSpec {
        CameraSpec {
            eye,
            target,
            fov_y_deg,
            aspect: None,
        }
    }
}

/// An isotropic point light: radiant intensity in W/sr per linear-RGB channel.
pub struct PointLight {
    pub position: V3,
    pub intensity: [f64; 3],
}

impl PointLight {
    /// A white light: `w_per_sr` in every channel.
    pub const fn white(position: V3, w_per_sr: f64) -> PointLight {
        PointLight {
            position,
            intensity: [w_per_sr; 3],
        }
    }
}

/// The `--camera` and `--light` arguments that give a viewer this camera and light (a README's
/// "Camera and light" block).
pub fn view_args(camera: &CameraSpec, light: &PointLight) -> String {
    let ([ex, ey, ez], [gx, gy, gz], fov) = (camera.eye, camera.target, camera.fov_y_deg);
    let ([lx, ly, lz], [r, g, b]) = (light.position, light.intensity);
    format!("--camera {ex},{ey},{ez}:{gx},{gy},{gz}:{fov}\n--light point:{lx},{ly},{lz}:{r},{g},{b}")
}

/// A whole scene as the writers need it.
pub struct SceneDesc {
    /// File stem, e.g. `cornell-box`.
    pub name: String,
    pub parts: Vec<Part>,
    pub materials: Vec<Material>,
    pub camera: CameraSpec,
    /// The scene's point light; `None` for a scene lit by its emissive materials alone.
    pub light: Option<PointLight>,
}

impl SceneDesc {
    pub fn new(
        name: impl Into<String>,
        parts: Vec<Part>,
        materials: Vec<Material>,
        camera: CameraSpec,
        light: PointLight,
    ) -> SceneDesc {
        SceneDesc {
            name: name.into(),
            parts,
            materials,
            camera,
            light: Some(light),
        }
    }

    /// Triangles after fan triangulation of every polygon, in f32 as both files store them.
    pub fn triangles(&self) -> Vec<[[f32; 3]; 3]> {
        let mut out = Vec::new();
        for part in &self.parts {
            for poly in &part.polys {
                let p: Vec<[f32; 3]> = poly.iter().map(|v| to_f32(*v)).collect();
                for i in 1..p.len() - 1 {
                    out.push([p[0], p[i], p[i + 1]]);
                }
            }
        }
        out
    }
}

/// Rounds a coordinate to the micrometre, then to f32 (what both file formats carry).
pub fn to_f32(v: V3) -> [f32; 3] {
    v.map(|c| ((c * 1e6).round() / 1e6) as f32)
}

/// Area of a triangle given in f32, computed in f64.
pub fn tri_area(t: &[[f32; 3]; 3]) -> f64 {
    let p = t.map(|v| v.map(f64::from));
    0.5 * length(cross(sub(p[1], p[0]), sub(p[2], p[0])))
}

/// A rigid transform: rotation about +Y by `yaw` radians, then translation.
#[derive(Clone, Copy)]
pub struct Xf {
    pub yaw: f64,
    pub offset: V3,
}

impl Xf {
    pub const IDENTITY: Xf = Xf {
        yaw: 0.0,
        offset: [0.0; 3],
    };

    pub fn new(yaw: f64, offset: V3) -> Xf {
        Xf { yaw, offset }
    }

    pub fn apply(&self, p: V3) -> V3 {
        let (s, c) = self.yaw.sin_cos();
        // Right-handed rotation about +Y: +Z turns towards +X.
        [
            c * p[0] + s * p[2] + self.offset[0],
            p[1] + self.offset[1],
            -s * p[0] + c * p[2] + self.offset[2],
        ]
    }
}

/// Which faces of a box to emit.
#[derive(Clone, Copy)]
pub struct Faces {
    pub bottom: bool,
    pub top: bool,
}

impl Faces {
    pub const ALL: Faces = Faces {
        bottom: true,
        top: true,
    };
}

/// The six (or fewer) outward-facing quads of the axis-aligned box `lo..hi`, transformed.
pub fn cuboid(lo: V3, hi: V3, xf: Xf, faces: Faces) -> Vec<Vec<V3>> {
    let c = |i: usize| -> V3 {
        [
            if i & 1 == 0 { lo[0] } else { hi[0] },
            if i & 2 == 0 { lo[1] } else { hi[1] },
            if i & 4 == 0 { lo[2] } else { hi[2] },
        ]
    };
    // Corner index bits: x = 1, y = 2, z = 4. Each quad is CCW seen from outside.
    let mut quads: Vec<[usize; 4]> = vec![
        [0, 4, 6, 2], // -X
        [1, 3, 7, 5], // +X
        [0, 1, 5, 4], // -Y (bottom)
        [2, 6, 7, 3], // +Y (top)
        [0, 2, 3, 1], // -Z
        [4, 5, 7, 6], // +Z
    ];
    if !faces.top {
        quads.remove(3);
    }
    if !faces.bottom {
        quads.remove(2);
    }
    quads
        .iter()
        .map(|q| q.iter().map(|&i| xf.apply(c(i))).collect())
        .collect()
}

/// A closed cylinder from `a` to `b` with `segments` sides; caps are triangle fans around
/// their centre. Outward-facing, transformed by `xf`.
pub fn cylinder(a: V3, b: V3, radius: f64, segments: usize, xf: Xf) -> Vec<Vec<V3>> {
    let axis = normalize(sub(b, a));
    let helper = if axis[1].abs() < 0.9 {
        [0.0, 1.0, 0.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let u = normalize(cross(helper, axis));
    let v = cross(axis, u);
    let ring = |centre: V3| -> Vec<V3> {
        (0..segments)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / segments as f64;
                add(centre, add(scale(u, radius * t.cos()), scale(v, radius * t.sin())))
            })
            .collect()
    };
    let (ra, rb) = (ring(a), ring(b));
    let mut polys = Vec::new();
    for i in 0..segments {
        let j = (i + 1) % segments;
        // u × v = axis, so increasing angle is CCW seen from the `b` end.
        polys.push(vec![ra[i], ra[j], rb[j], rb[i]]);
        polys.push(vec![b, rb[i], rb[j]]);
        polys.push(vec![a, ra[j], ra[i]]);
    }
    polys
        .into_iter()
        .map(|p| p.into_iter().map(|q| xf.apply(q)).collect())
        .collect()
}

/// An axis-aligned rectangle in the plane `axis = at`, spanning `r0` on the first other axis
/// and `r1` on the second (X→(Y,Z), Y→(Z,X), Z→(X,Y)), facing `+axis` if `positive`.
pub fn rect(axis: usize, at: f64, r0: [f64; 2], r1: [f64; 2], positive: bool) -> Vec<V3> {
    let (a0, a1) = ((axis + 1) % 3, (axis + 2) % 3);
    let p = |s: f64, t: f64| {
        let mut v = [0.0; 3];
        v[axis] = at;
        v[a0] = s;
        v[a1] = t;
        v
    };
    // (a0, a1, axis) is a right-handed cyclic order, so this order is CCW seen from +axis.
    let q = vec![p(r0[0], r1[0]), p(r0[1], r1[0]), p(r0[1], r1[1]), p(r0[0], r1[1])];
    if positive {
        q
    } else {
        q.into_iter().rev().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn centroid(p: &[V3]) -> V3 {
        scale(p.iter().fold([0.0; 3], |s, v| add(s, *v)), 1.0 / p.len() as f64)
    }

    #[test]
    fn cuboid_faces_point_outwards() {
        let polys = cuboid([0.0; 3], [1.0, 2.0, 3.0], Xf::new(0.3, [1.0, 0.0, 0.0]), Faces::ALL);
        let c = Xf::new(0.3, [1.0, 0.0, 0.0]).apply([0.5, 1.0, 1.5]);
        let area: f64 = polys.iter().map(|p| 0.5 * length(newell(p))).sum();
        assert!((area - 2.0 * (2.0 + 3.0 + 6.0)).abs() < 1e-9);
        for p in &polys {
            assert!(dot(newell(p), sub(centroid(p), c)) > 0.0);
        }
    }

    #[test]
    fn cylinder_faces_point_outwards() {
        for (a, b) in [([0.0; 3], [0.0, 1.0, 0.0]), ([0.0; 3], [1.0, 0.0, 0.2])] {
            let polys = cylinder(a, b, 0.1, 8, Xf::IDENTITY);
            let c = scale(add(a, b), 0.5);
            assert_eq!(polys.len(), 24);
            for p in &polys {
                assert!(dot(newell(p), sub(centroid(p), c)) > 0.0);
            }
        }
    }

    #[test]
    fn rect_faces_the_requested_side() {
        for axis in 0..3 {
            for positive in [true, false] {
                let n = newell(&rect(axis, 0.0, [0.0, 1.0], [0.0, 2.0], positive));
                assert!((n[axis] - if positive { 4.0 } else { -4.0 }).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn yaw_turns_z_towards_x() {
        let p = Xf::new(std::f64::consts::FRAC_PI_2, [0.0; 3]).apply([0.0, 0.0, 1.0]);
        assert!((p[0] - 1.0).abs() < 1e-12 && p[2].abs() < 1e-12);
    }
}
