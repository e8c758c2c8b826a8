//! `scenes`: writes the project's own test scenes (OBJ + MTL + glTF + README) and checks them.
//!
//! Usage: `scenes [--out DIR] [--check]`. Without `--check`, (re)writes every file under DIR
//! (default: the workspace's `scenes/`). With `--check`, writes nothing: it verifies that the
//! files under DIR are exactly what the generator produces, loads every glTF with the `gltf`
//! crate and every OBJ with `tobj` and compares them (same triangles, same area, same
//! albedos), and checks cameras, lights and, by ray casting, that closed scenes are closed.

mod chairs;
mod check;
mod color;
mod cornell;
mod courtyard;
mod gltf_out;
mod mesh;
mod obj;
mod two_rooms;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};

use mesh::{tri_area, SceneDesc};

const GENERATOR: &str = "prm xtask scenes";

/// Triangle count, total area (m²) and bounds of a scene, as written.
pub struct Stats {
    pub triangles: usize,
    pub area: f64,
    pub lo: [f32; 3],
    pub hi: [f32; 3],
}

impl Stats {
    pub fn of(scene: &SceneDesc) -> Stats {
        let tris = scene.triangles();
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in tris.iter().flatten() {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        Stats {
            triangles: tris.len(),
            area: tris.iter().map(tri_area).sum(),
            lo,
            hi,
        }
    }

    pub fn bounds_text(&self) -> String {
        let f = |v: [f32; 3]| format!("({}, {}, {})", v[0], v[1], v[2]);
        format!("{} .. {} m", f(self.lo), f(self.hi))
    }
}

/// How the ray-cast self-check treats a scene.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Enclosure {
    /// Open on one side (the Cornell box): rays may escape.
    Open,
    /// Fully closed: every ray from the light must hit a front face.
    Closed,
    /// Closed, and no ray from the light may reach x ≥ `two_rooms::WALL_X1` (room B).
    ClosedNoLeak,
    /// Closed, and some rays from the light must reach room B (through the door).
    ClosedWithDoor,
}

/// One output directory: its scenes and its README.
pub struct Bundle {
    pub dir: &'static str,
    pub summary: &'static str,
    pub scenes: Vec<(SceneDesc, Enclosure)>,
    pub readme: String,
}

impl Bundle {
    /// A directory of one scene, its README written from the scene's [`Stats`].
    fn one(
        dir: &'static str,
        summary: &'static str,
        scene: SceneDesc,
        enclosure: Enclosure,
        readme: impl FnOnce(&Stats) -> String,
    ) -> Bundle {
        let readme = readme(&Stats::of(&scene));
        Bundle {
            dir,
            summary,
            scenes: vec![(scene, enclosure)],
            readme,
        }
    }
}

pub fn bundles() -> Vec<Bundle> {
    let open = two_rooms::scene(false);
    let closed = two_rooms::scene(true);
    let rooms_readme = two_rooms::readme(&Stats::of(&open), &Stats::of(&closed));
    vec![
        Bundle::one(
            "cornell-box",
            "the Cornell box from its published measurements: colour bleeding, soft indirect light",
            cornell::scene(),
            Enclosure::Open,
            cornell::readme,
        ),
        Bundle::one(
            "cornell-box-lamps",
            "the Cornell box lit by two small emissive ceiling lamps of different colours: emitter groups",
            cornell::lamps_scene(),
            Enclosure::Open,
            cornell::lamps_readme,
        ),
        Bundle::one(
            "courtyard",
            "a yard open to the sky, walls and a block, no light of its own: sky light",
            courtyard::scene(),
            Enclosure::Open,
            courtyard::readme,
        ),
        Bundle::one(
            "chairs",
            "a closed dining room, six chairs around a table, ~3,000 triangles: small thin parts, contact shadows",
            chairs::scene(),
            Enclosure::Closed,
            chairs::readme,
        ),
        Bundle {
            dir: "two-rooms",
            summary: "two rooms sharing a 5 cm wall with a door (`two-rooms`) or a shut door (`two-rooms-closed`): light leaks",
            scenes: vec![(open, Enclosure::ClosedWithDoor), (closed, Enclosure::ClosedNoLeak)],
            readme: rooms_readme,
        },
    ]
}

/// Every file the generator writes, as (path relative to the output directory, contents).
pub fn files() -> Vec<(PathBuf, String)> {
    let bundles = bundles();
    let mut out = Vec::new();
    let mut index = String::from(
        "# Test scenes\n\nWritten by our own code: `cargo run -p xtask -- scenes` regenerates every file here\n\
         (`xtask/src/scenes/`), `cargo run -p xtask -- scenes --check` verifies them. Conventions:\n\
         right-handed, +Y up, metres; OBJ with positive indices; glTF 2.0 with an embedded buffer.\n\n",
    );
    for b in &bundles {
        let dir = Path::new(b.dir);
        for (scene, _) in &b.scenes {
            let s = Stats::of(scene);
            let header = vec![
                format!(
                    "{}: generated by `cargo run -p xtask -- scenes`; do not edit.",
                    scene.name
                ),
                "Right-handed, +Y up, metres. See README.md beside this file.".to_string(),
                format!("{} triangles, total area {:.6} m^2.", s.triangles, s.area),
            ];
            let mtl = format!("{}.mtl", scene.name);
            out.push((
                dir.join(format!("{}.obj", scene.name)),
                obj::write_obj(scene, &mtl, &header),
            ));
            out.push((dir.join(&mtl), obj::write_mtl(scene, &header)));
            out.push((
                dir.join(format!("{}.gltf", scene.name)),
                gltf_out::write_gltf(scene, GENERATOR),
            ));
        }
        out.push((dir.join("README.md"), b.readme.clone()));
        writeln!(index, "- [`{}/`]({}/README.md): {}.", b.dir, b.dir, b.summary).unwrap();
    }
    out.push((PathBuf::from("README.md"), index));
    out
}

fn default_out() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(|p| p.join("scenes"))
        .unwrap_or_else(|| "scenes".into())
}

/// Entry point: `args` are the arguments after `scenes`.
pub fn run(args: &[String]) -> anyhow::Result<()> {
    let mut out = default_out();
    let mut do_check = false;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--out" => out = it.next().context("--out needs a directory")?.into(),
            "--check" => do_check = true,
            "-h" | "--help" => {
                println!("usage: xtask scenes [--out DIR] [--check]");
                return Ok(());
            }
            other => {
                bail!("unknown argument {other:?} (usage: xtask scenes [--out DIR] [--check])")
            }
        }
    }
    if do_check {
        return check::run(&out);
    }
    for (rel, text) in files() {
        let path = out.join(&rel);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
        }
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    for b in bundles() {
        for (scene, _) in &b.scenes {
            let s = Stats::of(scene);
            println!("{}: {} triangles, area {:.6} m²", scene.name, s.triangles, s.area);
        }
    }
    Ok(())
}
