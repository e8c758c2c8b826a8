//! The chairs scene: a closed dining room with six chairs around a table, about 3,000 triangles.
//!
//! In the spirit of the paper's chairs test scene; also a shelf and a sideboard. All dimensions
//! are ours (ordinary furniture sizes), not measured from any model.

use std::f64::consts::TAU;

use super::mesh::{
    cuboid, cylinder, rect, view_args, CameraSpec, Faces, Material, Part, PointLight, SceneDesc, Xf, V3,
};

/// Room interior: x ∈ [0, W], y ∈ [0, H], z ∈ [0, D] (m).
pub const ROOM: V3 = [6.0, 2.8, 5.0];
/// Table centre on the floor.
pub const TABLE: V3 = [3.0, 0.0, 2.5];
/// Chair seat centres lie on this circle around the table (m).
pub const CHAIR_RADIUS: f64 = 0.95;
pub const CHAIRS: usize = 6;

/// Above the table, 4 W/sr.
pub const LIGHT: PointLight = PointLight::white([3.0, 2.3, 2.5], 4.0);
/// Eye, target, vertical field of view (°).
pub const CAMERA: CameraSpec = CameraSpec::free_aspect([0.6, 1.6, 0.6], [3.0, 0.7, 2.5], 60.0);

const NO_BOTTOM: Faces = Faces {
    bottom: false,
    top: true,
};
const SIDES_ONLY: Faces = Faces {
    bottom: false,
    top: false,
};

/// Materials: (name, albedo, what it is).
pub const MATERIALS: [(&str, [f64; 3], &str); 9] = [
    ("wall_white", [0.75, 0.75, 0.75], "three walls"),
    (
        "wall_terracotta",
        [0.62, 0.33, 0.22],
        "back wall (z = 5), for colour bleeding",
    ),
    ("ceiling", [0.80, 0.80, 0.80], "ceiling"),
    ("floor_blue", [0.18, 0.27, 0.45], "floor"),
    ("chair_wood", [0.45, 0.28, 0.15], "chairs"),
    ("table_wood", [0.60, 0.42, 0.26], "table top"),
    ("table_base", [0.10, 0.10, 0.10], "table column and foot"),
    ("shelf_paint", [0.70, 0.68, 0.62], "bookshelf"),
    ("sideboard_green", [0.20, 0.40, 0.30], "sideboard"),
];

/// One chair in local coordinates (seat centre over the origin, the sitter facing +Z).
fn chair(xf: Xf) -> Vec<Vec<V3>> {
    let mut p = Vec::new();
    let (lx, lz, r, n) = (0.19, 0.18, 0.018, 8);
    // Legs, floor to seat underside.
    for (x, z) in [(-lx, -lz), (lx, -lz), (-lx, lz), (lx, lz)] {
        p.extend(cylinder([x, 0.0, z], [x, 0.42, z], r, n, xf));
    }
    // Seat.
    p.extend(cuboid([-0.22, 0.42, -0.21], [0.22, 0.45, 0.21], xf, Faces::ALL));
    // Back posts, seat top to 0.95 m, above the rear legs.
    for x in [-lx, lx] {
        p.extend(cylinder([x, 0.45, -lz], [x, 0.95, -lz], r, n, xf));
    }
    // Top and lower back rails between the posts, and four vertical slats between the rails.
    let rx = lx - r;
    p.extend(cuboid([-rx, 0.84, -0.195], [rx, 0.93, -0.165], xf, Faces::ALL));
    p.extend(cuboid([-rx, 0.52, -0.195], [rx, 0.56, -0.165], xf, Faces::ALL));
    for c in [-0.12, -0.04, 0.04, 0.12] {
        p.extend(cuboid(
            [c - 0.0175, 0.56, -0.19],
            [c + 0.0175, 0.84, -0.17],
            xf,
            SIDES_ONLY,
        ));
    }
    // Stretchers: two along each side, one front, one back.
    let s = lz - r;
    for x in [-lx, lx] {
        p.extend(cylinder([x, 0.16, -s], [x, 0.16, s], 0.01, n, xf));
    }
    for z in [-lz, lz] {
        p.extend(cylinder([-rx, 0.22, z], [rx, 0.22, z], 0.01, n, xf));
    }
    p
}

pub fn scene() -> SceneDesc {
    let [w, h, d] = ROOM;
    let mut parts = vec![
        Part::new("floor", "floor_blue", vec![rect(1, 0.0, [0.0, d], [0.0, w], true)]),
        Part::new("ceiling", "ceiling", vec![rect(1, h, [0.0, d], [0.0, w], false)]),
        Part::new(
            "walls",
            "wall_white",
            vec![
                rect(0, 0.0, [0.0, h], [0.0, d], true),
                rect(0, w, [0.0, h], [0.0, d], false),
                rect(2, 0.0, [0.0, w], [0.0, h], true),
            ],
        ),
        Part::new(
            "wall_back",
            "wall_terracotta",
            vec![rect(2, d, [0.0, w], [0.0, h], false)],
        ),
    ];

    // Round table: top, column, foot.
    let [tx, _, tz] = TABLE;
    let none = Xf::IDENTITY;
    parts.push(Part::new(
        "table_top",
        "table_wood",
        cylinder([tx, 0.72, tz], [tx, 0.76, tz], 0.6, 48, none),
    ));
    let mut base = cylinder([tx, 0.06, tz], [tx, 0.72, tz], 0.05, 24, none);
    base.extend(cylinder([tx, 0.0, tz], [tx, 0.06, tz], 0.3, 32, none));
    parts.push(Part::new("table_base", "table_base", base));

    // Chairs on a circle, each turned to face the table centre.
    for i in 0..CHAIRS {
        let a = TAU * (i as f64 + 0.5) / CHAIRS as f64;
        let (dx, dz) = (CHAIR_RADIUS * a.cos(), CHAIR_RADIUS * a.sin());
        let yaw = (-dx).atan2(-dz);
        parts.push(Part::new(
            format!("chair_{}", i + 1),
            "chair_wood",
            chair(Xf::new(yaw, [tx + dx, 0.0, tz + dz])),
        ));
    }

    // Bookshelf against the +X wall, 2 cm off it: two sides, a back, five shelves.
    let (x0, x1, z0, z1) = (5.62, 5.98, 1.0, 1.9);
    let mut shelf = vec![];
    shelf.extend(cuboid([x0, 0.0, z0], [x1, 2.0, z0 + 0.02], none, NO_BOTTOM));
    shelf.extend(cuboid([x0, 0.0, z1 - 0.02], [x1, 2.0, z1], none, NO_BOTTOM));
    shelf.extend(cuboid(
        [x1 - 0.02, 0.0, z0 + 0.02],
        [x1, 2.0, z1 - 0.02],
        none,
        NO_BOTTOM,
    ));
    for y in [0.05, 0.5, 0.95, 1.4, 1.85] {
        shelf.extend(cuboid(
            [x0, y, z0 + 0.02],
            [x1 - 0.02, y + 0.02, z1 - 0.02],
            none,
            Faces::ALL,
        ));
    }
    parts.push(Part::new("shelf", "shelf_paint", shelf));

    // Sideboard against the back wall: body on four short legs, a slightly larger top.
    let (x0, x1, z0, z1) = (1.5, 3.3, 4.5, 4.97);
    let mut sb = vec![];
    sb.extend(cuboid([x0, 0.12, z0], [x1, 0.85, z1 - 0.01], none, Faces::ALL));
    sb.extend(cuboid(
        [x0 - 0.02, 0.85, z0 - 0.02],
        [x1 + 0.02, 0.88, z1],
        none,
        Faces::ALL,
    ));
    for (x, z) in [
        (x0 + 0.05, z0 + 0.05),
        (x1 - 0.09, z0 + 0.05),
        (x0 + 0.05, z1 - 0.1),
        (x1 - 0.09, z1 - 0.1),
    ] {
        sb.extend(cuboid([x, 0.0, z], [x + 0.04, 0.12, z + 0.04], none, NO_BOTTOM));
    }
    parts.push(Part::new("sideboard", "sideboard_green", sb));

    let materials = MATERIALS
        .iter()
        .map(|(name, albedo, _)| Material::diffuse(name, *albedo))
        .collect();
    SceneDesc::new("chairs", parts, materials, CAMERA, LIGHT)
}

pub fn readme(s: &super::Stats) -> String {
    let table: String = MATERIALS
        .iter()
        .map(|(n, a, what)| format!("| {n} | {:.2} | {:.2} | {:.2} | {what} |\n", a[0], a[1], a[2]))
        .collect();
    let l = LIGHT.intensity[0];
    let drop = LIGHT.position[1] - 0.76;
    format!(
        "# chairs

Tests: a furnished, closed room of about 3,000 triangles (like the paper's chairs scene): many
small, thin, close-together parts (chair legs, slats, stretchers) for contact shadows and
occlusion under the table, and inter-reflections between coloured surfaces.

Generated by `cargo run -p xtask -- scenes` (`xtask/src/scenes/chairs.rs`); do not edit by hand.

## Files

- `chairs.obj` + `chairs.mtl`: parts `floor`, `ceiling`, `walls`, `wall_back`, `table_top`,
  `table_base`, `chair_1`..`chair_6`, `shelf`, `sideboard`; quads and triangles, positive indices.
- `chairs.gltf`: the same triangles and positions, flat normals, a point light and a camera.

Triangles: {tris}. Total area: {area:.6} m². Bounds: {bounds}.

## Source of the numbers

Everything is made up by us to ordinary furniture sizes (metres): a {rw} × {rh} × {rd} m room
(x × y × z, closed on all six sides, every wall facing inwards); a round table (top 1.2 m
across, 0.76 m high) at ({tx}, {tz}); {nc} chairs (seat 0.44 × 0.42 m at 0.45 m, back to
0.95 m; round legs, posts and stretchers with 8 sides; four slats) on a {cr} m circle around
it, each facing the table; a bookshelf 2 cm off the +X wall and a sideboard against the back
wall. Parts are closed boxes and cylinders, except that box faces resting on the floor, and the
ends of the back slats (against the rails), are left out. Vertices are not shared between parts.

## Albedos (linear RGB, chosen)

| material | R | G | B | used for |
| --- | --- | --- | --- | --- |
{table}
## Camera and light

```
{view}
```

The camera stands in a corner looking down at the table; the light hangs {drop:.2} m above the
table top, giving it about {e:.2} W/m² directly (the glTF holds the same light, `intensity`
{l} read as W/sr, and camera).
",
        tris = s.triangles,
        area = s.area,
        bounds = s.bounds_text(),
        rw = ROOM[0],
        rh = ROOM[1],
        rd = ROOM[2],
        tx = TABLE[0],
        tz = TABLE[2],
        nc = CHAIRS,
        cr = CHAIR_RADIUS,
        view = view_args(&CAMERA, &LIGHT),
        e = l / (drop * drop),
    )
}
