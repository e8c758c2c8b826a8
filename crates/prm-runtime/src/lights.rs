//! The lights of a frame as the shaders see them, and their shadow views: a cube (6 perspective
//! views) for point lights, one perspective view for spot lights of half angle up to
//! [`SPOT_SINGLE_VIEW_MAX_DEG`] (a cube beyond, where a single frustum would waste its texels),
//! one perspective view of its own aspect for rectangular spots, and for directional lights an
//! orthographic map of the scene's bounding sphere cut into `sun_tiles`² views, one tile each
//! (row-major from the map's bottom-left, each one shadow texel wider on every side so that
//! the 2×2 filter at its edge reads its own texels; `lights.wgsl` picks the tile). Depth is [0, 1]
//! (wgpu), linearised in `lights.wgsl`. An engine that renders its own shadow maps renders these
//! views, in this order, one layer each ([`Shadows::External`](crate::Shadows)).

use glam::{Mat4, Vec3};
use prm_scene::{Aabb, Light};

use crate::shared::{GpuLight, GpuView, LightKind};

/// Right-handed perspective projection with WebGPU's NDC (z in [0, 1], y up).
pub fn perspective(fov_y: f32, aspect: f32, near: f32, far: f32) -> Mat4 {
    glam::camera::rh::proj::directx::perspective(fov_y, aspect, near, far)
}

/// Right-handed orthographic projection with WebGPU's NDC (z in [0, 1], y up).
pub fn orthographic(left: f32, right: f32, bottom: f32, top: f32, near: f32, far: f32) -> Mat4 {
    glam::camera::rh::proj::directx::orthographic(left, right, bottom, top, near, far)
}

/// Right-handed view matrix from `eye` looking along `dir`.
pub fn look_to(eye: Vec3, dir: Vec3, up: Vec3) -> Mat4 {
    glam::camera::rh::view::look_to_mat4(eye, dir, up)
}

/// Largest spot half angle that gets one perspective view.
pub const SPOT_SINGLE_VIEW_MAX_DEG: f32 = 60.0;

/// The six cube-face directions, in the order `lights.wgsl` selects them (+X −X +Y −Y +Z −Z).
const CUBE: [(Vec3, Vec3); 6] = [
    (Vec3::X, Vec3::NEG_Y),
    (Vec3::NEG_X, Vec3::NEG_Y),
    (Vec3::Y, Vec3::Z),
    (Vec3::NEG_Y, Vec3::NEG_Z),
    (Vec3::Z, Vec3::NEG_Y),
    (Vec3::NEG_Z, Vec3::NEG_Y),
];

fn corners(b: &Aabb) -> [Vec3; 8] {
    let mut c = [Vec3::ZERO; 8];
    for (i, p) in c.iter_mut().enumerate() {
        *p = Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        );
    }
    c
}

fn cols(m: Mat4) -> [[f32; 4]; 4] {
    m.to_cols_array_2d()
}

/// GPU lights and their shadow views for `lights` in a scene of bounds `bounds`, shadow maps of
/// `resolution`² texels and `sun_tiles`² tiles (at least 1) for a directional light: light `i`'s
/// views are layers `first_view .. first_view + view_count`.
pub fn shadow_views(lights: &[Light], bounds: &Aabb, resolution: u32, sun_tiles: u32) -> (Vec<GpuLight>, Vec<GpuView>) {
    let mut views = ViewList {
        bounds,
        res: resolution as f32,
        diag: bounds.diagonal().max(1e-3),
        views: Vec::new(),
    };
    let gpu_lights = lights
        .iter()
        .map(|light| {
            let first_view = views.views.len() as u32;
            let gl = match *light {
                Light::Point { position, intensity } => views.point_light(position, intensity),
                Light::Spot {
                    position,
                    direction,
                    angle,
                    intensity,
                } => views.spot_light(position, direction, angle, intensity),
                Light::Rect {
                    position,
                    direction,
                    up,
                    half_angles,
                    intensity,
                } => views.rect_light(position, direction, up, half_angles, intensity),
                Light::Directional { direction, irradiance } => views.sun_light(direction, irradiance, sun_tiles),
            };
            GpuLight { first_view, ..gl }
        })
        .collect();
    (gpu_lights, views.views)
}

/// The shadow views of a frame's lights so far, and what they are fitted to.
struct ViewList<'a> {
    bounds: &'a Aabb,
    /// Shadow-map side in texels.
    res: f32,
    /// The scene's diagonal (at least 1 mm).
    diag: f32,
    views: Vec<GpuView>,
}

impl ViewList<'_> {
    /// A far plane from `p` beyond every corner of the scene.
    fn far_from(&self, p: Vec3) -> f32 {
        corners(self.bounds)
            .iter()
            .map(|c| c.distance(p))
            .fold(0.0f32, f32::max)
            .max(self.diag * 1e-2)
            * 1.01
    }

    /// Appends a perspective view from `eye` along `dir` of vertical field `fov_y` and `aspect`,
    /// whose texels span `texel` at unit distance.
    fn push_perspective(&mut self, eye: Vec3, dir: Vec3, up: Vec3, [fov_y, aspect]: [f32; 2], texel: f32) {
        let near = self.diag * 1e-3;
        let far = self.far_from(eye);
        let proj = perspective(fov_y, aspect, near, far);
        self.views.push(GpuView {
            view_proj: cols(proj * look_to(eye, dir, up)),
            texel,
            near,
            far,
            orthographic: 0,
        });
    }

    /// Appends the six views of a cube around `p`.
    fn push_cube(&mut self, p: Vec3) {
        for (dir, up) in CUBE {
            self.push_perspective(p, dir, up, [std::f32::consts::FRAC_PI_2, 1.0], 2.0 / self.res);
        }
    }

    /// A point light: a cube of views.
    fn point_light(&mut self, position: Vec3, intensity: Vec3) -> GpuLight {
        self.push_cube(position);
        GpuLight {
            kind: LightKind::Point as u32,
            view_count: 6,
            cos_cutoff: -2.0,
            position: position.to_array(),
            direction: [0.0; 3],
            color: intensity.to_array(),
            ..Default::default()
        }
    }

    /// A spot light: one view up to [`SPOT_SINGLE_VIEW_MAX_DEG`], a cube beyond.
    fn spot_light(&mut self, position: Vec3, direction: Vec3, angle: f32, intensity: Vec3) -> GpuLight {
        let view_count = if angle.to_degrees() <= SPOT_SINGLE_VIEW_MAX_DEG {
            let fov = (angle * 2.0 * 1.05 + 2f32.to_radians()).min(170f32.to_radians());
            let up = if direction.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y };
            let texel = 2.0 * (fov * 0.5).tan() / self.res;
            self.push_perspective(position, direction, up, [fov, 1.0], texel);
            1
        } else {
            self.push_cube(position);
            6
        };
        GpuLight {
            kind: LightKind::Spot as u32,
            view_count,
            cos_cutoff: angle.cos(),
            position: position.to_array(),
            direction: direction.normalize().to_array(),
            color: intensity.to_array(),
            ..Default::default()
        }
    }

    /// A rectangular spot: one view of the frustum's own aspect, 5% and 1° wider than it like a
    /// spot's.
    fn rect_light(
        &mut self,
        position: Vec3,
        direction: Vec3,
        up: Vec3,
        half_angles: [f32; 2],
        intensity: Vec3,
    ) -> GpuLight {
        let widen = |a: f32| (a * 1.05 + 1f32.to_radians()).min(88f32.to_radians()).tan();
        let (tx, ty) = (widen(half_angles[0]), widen(half_angles[1]));
        self.push_perspective(
            position,
            direction,
            up,
            [2.0 * ty.atan(), tx / ty],
            2.0 * tx.max(ty) / self.res,
        );
        GpuLight {
            kind: LightKind::Rect as u32,
            view_count: 1,
            cos_cutoff: -2.0,
            position: position.to_array(),
            tan_x: half_angles[0].tan(),
            direction: direction.normalize().to_array(),
            tan_y: half_angles[1].tan(),
            color: intensity.to_array(),
            up: up.normalize().to_array(),
            ..Default::default()
        }
    }

    /// A directional light: an orthographic map of the scene's bounding sphere in `sun_tiles`²
    /// tiles (at least 1), row-major from the bottom-left, each one texel wider on every side.
    fn sun_light(&mut self, direction: Vec3, irradiance: Vec3, sun_tiles: u32) -> GpuLight {
        let d = direction.normalize();
        let centre = (self.bounds.min + self.bounds.max) * 0.5;
        let r = self.diag * 0.5;
        let eye = centre - d * 2.0 * r;
        let up = if d.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y };
        let (near, far) = (0.5 * r, 3.5 * r);
        let view = look_to(eye, d, up);
        // The view's own vertical (look_to's `u`), which lights.wgsl measures tiles along.
        let map_up = d.cross(up).normalize().cross(d);
        let tiles = sun_tiles.max(1);
        let step = 2.0 * r / tiles as f32;
        let pad = step / self.res;
        for iy in 0..tiles {
            for ix in 0..tiles {
                let (x0, y0) = (-r + ix as f32 * step, -r + iy as f32 * step);
                let proj = orthographic(x0 - pad, x0 + step + pad, y0 - pad, y0 + step + pad, near, far);
                self.views.push(GpuView {
                    view_proj: cols(proj * view),
                    texel: (step + 2.0 * pad) / self.res,
                    near,
                    far,
                    orthographic: 1,
                });
            }
        }
        GpuLight {
            kind: LightKind::Directional as u32,
            view_count: tiles * tiles,
            cos_cutoff: -2.0,
            position: centre.to_array(),
            tan_x: r,
            direction: d.to_array(),
            color: irradiance.to_array(),
            up: map_up.to_array(),
            ..Default::default()
        }
    }
}
