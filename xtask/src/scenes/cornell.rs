//! The Cornell box from the Cornell Program of Computer Graphics' published measurements.
//!
//! Geometry: the "Cornell Box Data" page lists every surface as a quad in millimetres, already
//! with +Y up, the floor in the x–z plane and the open side at z = 0 facing the camera at
//! z = −800. That frame is right-handed as given: seen from the camera (looking +Z), +X is on
//! the left, which is where the red wall (x ≈ 556) is in the photographs. So the only change is
//! millimetres → metres. The page's vertex order is kept; it is counter-clockwise seen from the
//! inside of the room and from outside the blocks, i.e. every face faces the open volume.

use super::color::{cornell_reflectance, piecewise, round4, sampled_4nm, spectrum_to_rgb, CORNELL_LAMP};
use super::mesh::{CameraSpec, Material, Part, PointLight, SceneDesc, V3};

/// The point light's position (m): below the lamp centre, 48.8 mm under the ceiling.
pub const POINT_LIGHT: V3 = [0.278, 0.5, 0.2795];

/// Focal length and film height (m) from the data page's camera section.
pub const FOCAL_LENGTH: f64 = 0.035;
pub const FILM_HEIGHT: f64 = 0.025;

type Quad = [[f64; 3]; 4];

/// The surfaces exactly as listed on the data page, one quad a line: part name, material, then
/// the four corners' x y z in mm.
const MEASURED: &str = include_str!("cornell_box.txt");

/// (part name, material, quads in mm) from [`MEASURED`], the parts in the page's order.
fn measured() -> Vec<(&'static str, &'static str, Vec<Quad>)> {
    let mut parts: Vec<(&'static str, &'static str, Vec<Quad>)> = Vec::new();
    for line in MEASURED.lines().filter(|l| !l.starts_with('#') && !l.trim().is_empty()) {
        let mut words = line.split_whitespace();
        let (name, material) = (words.next().unwrap(), words.next().unwrap());
        let v: Vec<f64> = words.map(|w| w.parse().unwrap()).collect();
        assert_eq!(v.len(), 12, "a quad is four corners: {line}");
        let quad: Quad = std::array::from_fn(|i| [v[3 * i], v[3 * i + 1], v[3 * i + 2]]);
        match parts.last_mut() {
            Some((last, _, quads)) if *last == name => quads.push(quad),
            _ => parts.push((name, material, vec![quad])),
        }
    }
    parts
}

/// Lamp emission as linear RGB (the page's radiance units), from its emission spectrum.
pub fn lamp_rgb() -> [f64; 3] {
    round4(spectrum_to_rgb(piecewise(&CORNELL_LAMP)))
}

/// Lamp area in m² (130 mm × 105 mm).
pub const LAMP_AREA: f64 = 0.130 * 0.105;

pub fn scene() -> SceneDesc {
    let parts = measured()
        .into_iter()
        .map(|(name, material, quads)| {
            let metres = |q: &Quad| q.iter().map(|p| p.map(|c| c / 1000.0)).collect();
            Part::new(name, material, quads.iter().map(metres).collect())
        })
        .collect();
    let materials = ["white", "red", "green"]
        .map(|name| Material::diffuse(name, round4(spectrum_to_rgb(sampled_4nm(&cornell_reflectance(name))))))
        .into();
    SceneDesc {
        name: "cornell-box".into(),
        parts,
        materials,
        camera: CameraSpec {
            eye: [0.278, 0.273, -0.8],
            target: [0.278, 0.273, 0.0],
            fov_y_deg: (2.0 * (FILM_HEIGHT / 2.0 / FOCAL_LENGTH).atan()).to_degrees(),
            aspect: Some(1.0),
        },
        light: Some(PointLight {
            position: POINT_LIGHT,
            intensity: point_light_intensity(),
        }),
    }
}

/// The point light's radiant intensity (W/sr): the lamp's on-axis radiant intensity
/// `Ke × area` (a Lambertian emitter of radiance Ke), so the floor under the lamp gets about
/// the irradiance the area lamp gives it.
pub fn point_light_intensity() -> [f64; 3] {
    lamp_rgb().map(|c| (c * LAMP_AREA * 1e4).round() / 1e4)
}

/// The two lamps of [`lamps_scene`]: name, material, corner (x, z) in metres, emission.
const LAMPS: [(&str, &str, [f64; 2], [f64; 3]); 2] = [
    ("warm_lamp", "lamp_warm", [0.10, 0.20], [40.0, 28.0, 10.0]),
    ("blue_lamp", "lamp_blue", [0.35, 0.25], [8.0, 16.0, 40.0]),
];
/// Side of each lamp (m) and its height, 1 mm under the ceiling.
const LAMP_SIDE: f64 = 0.1;
const LAMP_Y: f64 = 0.5478;

/// The box without its point light, lit by two 10 × 10 cm emissive lamps of different colours
/// just under its ceiling, facing down: two emitter groups.
pub fn lamps_scene() -> SceneDesc {
    let mut s = scene();
    s.name = "cornell-box-lamps".into();
    s.light = None;
    for (name, material, [x0, z0], emission) in LAMPS {
        let (x1, z1) = (x0 + LAMP_SIDE, z0 + LAMP_SIDE);
        // Counter-clockwise seen from below: the lamp faces down.
        let quad = vec![[x0, LAMP_Y, z0], [x1, LAMP_Y, z0], [x1, LAMP_Y, z1], [x0, LAMP_Y, z1]];
        s.parts.push(Part::new(name, material, vec![quad]));
        s.materials.push(Material {
            name: material.into(),
            albedo: [0.78; 3],
            emission: Some(emission),
        });
    }
    s
}

pub fn lamps_readme(s: &super::Stats) -> String {
    let lamp = |i: usize| {
        let (name, material, [x, z], [r, g, b]) = LAMPS[i];
        format!(
            "- `{name}` (material `{material}`): {side:.0} × {side:.0} cm at x {x:.2}..{x1:.2}, z {z:.2}..{z1:.2} m, \
             y = {LAMP_Y} m, facing down; `Ke` = ({r}, {g}, {b}) W/(m²·sr)",
            side = LAMP_SIDE * 100.0,
            x1 = x + LAMP_SIDE,
            z1 = z + LAMP_SIDE
        )
    };
    format!(
        "# cornell-box-lamps

Tests: emissive surfaces as dynamic lights, two emitter groups. The `cornell-box` scene (same
geometry, albedos and camera) without its point light, lit by two small lamps just under the
ceiling, each its own emissive material:

{a}
{b}

Generated by `cargo run -p xtask -- scenes` (`xtask/src/scenes/cornell.rs`); do not edit by hand.
`cornell-box-lamps.obj` + `.mtl` give the emission as `Ke`; `cornell-box-lamps.gltf` as
`emissiveFactor` × `KHR_materials_emissive_strength` (and has the camera; neither file has a
punctual light). Used by `tests/emitters.rs` and `cargo xtask eval --emitters`:

```sh
prm-bake bake scenes/cornell-box-lamps/cornell-box-lamps.gltf -o out/lamps.prm
prm-play out/lamps.prm --emitter lamp_warm=0.25 --emitter lamp_blue=1,0.5,2
```

Triangles: {tris}. Total area: {area:.6} m². Bounds: {bounds}.
",
        a = lamp(0),
        b = lamp(1),
        tris = s.triangles,
        area = s.area,
        bounds = s.bounds_text(),
    )
}

pub fn readme(s: &super::Stats) -> String {
    let sc = scene();
    let m = |n: &str| sc.materials.iter().find(|m| m.name == n).map(|m| m.albedo).unwrap();
    let (w, r, g) = (m("white"), m("red"), m("green"));
    // An albedo's cells in the README's table.
    let row = |c: [f64; 3]| format!("{:.4} | {:.4} | {:.4}", c[0], c[1], c[2]);
    let lamp = lamp_rgb();
    let i = point_light_intensity();
    format!(
        "# cornell-box

Tests: colour bleeding and soft indirect light in the classic closed-on-five-sides box with two
white blocks, against a scene whose every number is measured.

Generated by `cargo run -p xtask -- scenes` (`xtask/src/scenes/cornell.rs`); do not edit by hand.

## Files

- `cornell-box.obj` + `cornell-box.mtl`: one `o` per part — `floor`, `ceiling`, `back`, `left`
  (red), `right` (green), `short_block`, `tall_block` — quads with positive indices;
  the non-planar left wall is written as two explicit triangles.
- `cornell-box.gltf`: the same {tris} triangles with the same f32 positions (one node and mesh
  per part, flat per-face normals, embedded base64 buffer), the four materials as
  `baseColorFactor`, a `KHR_lights_punctual` point light and a perspective camera.

Triangles: {tris}. Total area: {area:.6} m². Bounds: {bounds}.

## Source of the numbers

All geometry, the camera, the reflectances and the lamp spectrum are from the Cornell
University Program of Computer Graphics page \"Cornell Box Data\" (the box with diffuse objects).
That data is in millimetres with +Y up, the floor in the x–z plane and the open side at z = 0;
it is right-handed as given (looking +Z from the camera, +X is to the left, where the red wall
is in the photographs), so it is only scaled mm → m. Surfaces face the open volume.

One deviation: the lamp quad (343..213 × 227..332 mm) is left out. The page lists it in the
ceiling's plane, where a panel would fight the ceiling in depth tests or, lowered a little,
form a thin gap that no shadow map of the point light resolves; the point light below replaces
it. `../cornell-box-lamps` is this box lit by emissive lamps instead of the point light.

## Albedos (linear RGB)

| material | R | G | B |
| --- | --- | --- | --- |
| white (floor, ceiling, back, blocks) | {w_row} |
| red (left wall) | {r_row} |
| green (right wall) | {g_row} |

Derived by our code (`xtask/src/scenes/color.rs`) from the published reflectance spectra
(400–700 nm every 4 nm): each spectrum, linearly interpolated, is integrated against the CIE 1931
2° colour-matching functions (analytic multi-lobe fit, Wyman, Sloan & Shirley 2013) in 1 nm
steps; XYZ goes to linear sRGB with the IEC 61966-2-1 matrix; each channel is then divided by
the value of a flat reflectance of 1 (white balance to the equal-energy illuminant), so a grey
surface stays grey. Negative channels would clamp to 0 (none do).

Why these and not the RGB values often quoted for this box (white ≈ 0.73, red ≈ (0.63, 0.065,
0.05), green ≈ (0.14, 0.45, 0.09)): white agrees, but those red and green numbers match the
spectra's values at single wavelengths (red's 0.62–0.66 plateau above 630 nm, green's 0.45–0.48
peak near 520 nm, its 0.14 near 680 nm), while each sRGB channel really sees a broad band. The
sRGB red channel responds mostly to 570–640 nm, where this red paint still rises from 0.07 to
0.6, so its R is {r0:.2}, not 0.63; likewise green's G is {g1:.2}. We keep the colorimetric values
so that a surface's RGB albedo is what the measured paint looks like under white light. Under
the lamp's own (reddish) spectrum instead of the flat one, red would be about (0.45, 0.04, 0.01):
the choice of white matters less than the band integration.

The lamp's emission spectrum (0, 8, 15.6, 18.4 at 400, 500, 600, 700 nm, piecewise linear)
reduced the same way gives `Ke` = ({k0:.4}, {k1:.4}, {k2:.4}) in the page's radiance units.

## Camera and light

```
--camera 0.278,0.273,-0.8:0.278,0.273,0:{fov:.4}
--light point:{lx},{ly},{lz}:{i0},{i1},{i2}
```

Camera: the page's camera — eye (278, 273, −800) mm looking +Z, up +Y, focal length 35 mm on a
25 × 25 mm film: vertical field of view 2·atan(12.5/35) = {fov:.4}°, aspect 1. In glTF it is a
node at the eye rotated 180° about +Y (glTF cameras look down −Z), `yfov` = {yfov:.6} rad,
`aspectRatio` 1.

Point light: ({lx}, {ly}, {lz}) m, under the lamp's centre and {below:.1} mm below the ceiling.
Radiant intensity per channel = `Ke` × lamp area (0.130 × 0.105 m²) = ({i0}, {i1}, {i2}) W/sr:
the area lamp's on-axis intensity. The floor under the lamp then gets ≈ {e:.2} W/m² (red)
from the point light, against ≈ {ea:.2} W/m² from the area lamp, which hangs a little higher.
In glTF: `color` = that / its largest channel, `intensity` =
the largest channel. The glTF spec calls `intensity` candela; this project's loader reads
`color × intensity` as W/sr per channel, with no 683 lm/W factor.
",
        tris = s.triangles,
        area = s.area,
        bounds = s.bounds_text(),
        w_row = row(w),
        r_row = row(r),
        g_row = row(g),
        r0 = r[0],
        g1 = g[1],
        k0 = lamp[0],
        k1 = lamp[1],
        k2 = lamp[2],
        fov = sc.camera.fov_y_deg,
        yfov = sc.camera.fov_y_deg.to_radians(),
        lx = POINT_LIGHT[0],
        ly = POINT_LIGHT[1],
        lz = POINT_LIGHT[2],
        below = (0.5488 - POINT_LIGHT[1]) * 1000.0,
        i0 = i[0],
        i1 = i[1],
        i2 = i[2],
        e = i[0] / (POINT_LIGHT[1] * POINT_LIGHT[1]),
        ea = i[0] / (0.5478f64 * 0.5478),
    )
}
