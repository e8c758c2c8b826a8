//! Bounded, deterministic mutation fuzzing of the OBJ and glTF loaders: never a panic, never a huge allocation.
//!
//! Small valid inputs (OBJ + MTL, glTF JSON + `.bin`, GLB) get random byte flips, truncations,
//! insertions and number replacements from a seeded xorshift generator; every mutant must load
//! to `Ok` or `Err`. A counting global allocator checks that no single allocation, and no peak,
//! is absurd for inputs of a few hundred bytes. A failure names the seed and keeps the input.

mod common;
use common::temp_case;
use std::alloc::{GlobalAlloc, Layout, System};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Counts live bytes, their peak and the largest single request.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static LARGEST: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            note_alloc(layout.size());
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            note_alloc(layout.size());
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            note_alloc(new_size);
        }
        p
    }
}

fn note_alloc(size: usize) {
    let live = LIVE.fetch_add(size, Ordering::Relaxed) + size;
    PEAK.fetch_max(live, Ordering::Relaxed);
    LARGEST.fetch_max(size, Ordering::Relaxed);
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// No single allocation may exceed this while loading inputs of a few hundred bytes (the
/// loaders' own validation bounds everything by the input's size; the limit on view-less
/// accessors is 1 Mi elements, 12 MiB as `[f32; 3]`).
const MAX_SINGLE_ALLOC: usize = 64 << 20;
/// Nor may the live total (both fuzz tests run at once, with the test harness).
const MAX_PEAK: usize = 512 << 20;

/// xorshift64*: small, seeded, deterministic.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Numbers that stress counts, offsets and indices.
const NASTY: &[&str] = &[
    "0",
    "-1",
    "1",
    "2",
    "3",
    "4",
    "255",
    "65535",
    "4294967295",
    "4294967296",
    "4000000000",
    "1000000",
    "2147483647",
    "-2147483648",
    "9223372036854775807",
    "18446744073709551615",
    "99999999999999999999999",
    "1e30",
    "-1e30",
    "nan",
    "inf",
    "0.5",
    "-0",
    "5126",
    "5123",
    "5121",
    "5120",
    "5122",
    "5125",
];

/// Applies 1–3 random mutations to `data`.
fn mutate(rng: &mut Rng, data: &mut Vec<u8>) {
    for _ in 0..1 + rng.below(3) {
        match rng.below(6) {
            // Flip one bit.
            0 if !data.is_empty() => {
                let i = rng.below(data.len());
                data[i] ^= 1 << rng.below(8);
            }
            // Replace a byte by a random one (often non-ASCII).
            1 if !data.is_empty() => {
                let i = rng.below(data.len());
                data[i] = rng.next() as u8;
            }
            // Truncate.
            2 => {
                let n = rng.below(data.len() + 1);
                data.truncate(n);
            }
            // Insert a few random bytes or a structural character.
            3 => {
                let i = rng.below(data.len() + 1);
                let insert: Vec<u8> = match rng.below(3) {
                    0 => {
                        let structural = b"/#\n {}[],:\"-";
                        vec![structural[rng.below(structural.len())]]
                    }
                    1 => (0..1 + rng.below(4)).map(|_| rng.next() as u8).collect(),
                    _ => NASTY[rng.below(NASTY.len())].as_bytes().to_vec(),
                };
                data.splice(i..i, insert);
            }
            // Delete a range.
            4 if !data.is_empty() => {
                let i = rng.below(data.len());
                let n = (1 + rng.below(8)).min(data.len() - i);
                data.drain(i..i + n);
            }
            // Replace a number (a run of digits, signs, dots, e) by a nasty one.
            _ => {
                let numbers: Vec<(usize, usize)> = number_spans(data);
                if numbers.is_empty() {
                    continue;
                }
                let (a, b) = numbers[rng.below(numbers.len())];
                let with = NASTY[rng.below(NASTY.len())].as_bytes().to_vec();
                data.splice(a..b, with);
            }
        }
    }
}

/// Byte ranges of the numbers in a text.
fn number_spans(data: &[u8]) -> Vec<(usize, usize)> {
    let is_num = |c: u8| c.is_ascii_digit() || matches!(c, b'-' | b'+' | b'.' | b'e' | b'E');
    let mut spans = Vec::new();
    let mut i = 0;
    while i < data.len() {
        if data[i].is_ascii_digit() {
            let mut a = i;
            while a > 0 && is_num(data[a - 1]) {
                a -= 1;
            }
            let mut b = i;
            while b < data.len() && is_num(data[b]) {
                b += 1;
            }
            spans.push((a, b));
            i = b;
        } else {
            i += 1;
        }
    }
    spans
}

/// Loads `scene` (whether it loaded) and turns a panic or an absurd allocation into a failure
/// message.
fn check_load(scene: &Path, what: &str) -> Result<bool, String> {
    let before_live = LIVE.load(Ordering::Relaxed);
    let result = catch_unwind(AssertUnwindSafe(|| prm_scene::load(scene)));
    let largest = LARGEST.load(Ordering::Relaxed);
    let peak = PEAK.load(Ordering::Relaxed);
    match result {
        Err(panic) => {
            let msg = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            Err(format!("{what}: panicked: {msg}"))
        }
        Ok(_) if largest > MAX_SINGLE_ALLOC => Err(format!(
            "{what}: allocated {largest} bytes at once (live before: {before_live})"
        )),
        Ok(_) if peak > MAX_PEAK => Err(format!("{what}: peak live memory {peak} bytes")),
        Ok(r) => Ok(r.is_ok()),
    }
}

/// Runs `cases` mutants: `build(rng, dir)` writes one and returns the file to load. On failure
/// the mutant's directory is kept (renamed after the seed) for reproduction.
///
/// `PRM_FUZZ_CASES` overrides the number of cases (for a longer run by hand).
fn fuzz(name: &str, cases: u64, build: impl Fn(&mut Rng, &Path) -> PathBuf) {
    let cases = std::env::var("PRM_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(cases);
    let mut failures = Vec::new();
    let (mut ok, mut err) = (0, 0);
    for case in 0..cases {
        let seed = 0x9e37_79b9_7f4a_7c15 ^ (case + 1).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        let mut rng = Rng(seed);
        let dir = temp_case(&format!("fuzz-{name}-case"));
        let file = build(&mut rng, &dir);
        let outcome = check_load(&file, &format!("{name} case {case} (seed {seed:#x})"));
        match outcome {
            Ok(true) => ok += 1,
            Ok(false) => err += 1,
            Err(_) => {}
        }
        if let Err(e) = outcome {
            let keep = std::env::temp_dir().join(format!("prm-scene-fuzz-{name}-failure-{case}"));
            let _ = std::fs::remove_dir_all(&keep);
            let _ = std::fs::rename(&dir.0, &keep);
            failures.push(format!("{e} — input kept in {}", keep.display()));
        }
    }
    eprintln!("{name}: {ok} mutants loaded, {err} were refused");
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

const OBJ: &str = "# a small valid scene\nmtllib s.mtl\no floor\nv 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\n\
vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 1 0\nusemtl red\nf 1/1/1 2/2/1 3/3/1 4/4/1\n\
g wall\nv 0 1 0 0.5 0.5 0.5\nusemtl white\nf -1 1 2\nf 5//1 2//1 1//1\n";
const MTL: &str = "newmtl red\nKd 0.8 0.1 0.1\nnewmtl white\nKd 0.7 0.7 0.7\nmap_Kd none.png\n";

#[test]
fn fuzz_obj_loader() {
    let base = temp_case("fuzz-obj-base");
    std::fs::write(base.join("s.mtl"), MTL).unwrap();
    std::fs::write(base.join("s.obj"), OBJ).unwrap();
    prm_scene::load(&base.join("s.obj")).expect("the unmutated OBJ loads");
    fuzz_pair("obj", ("s.obj", OBJ.as_bytes()), ("s.mtl", MTL.as_bytes()));
}

/// Fuzzes a scene of two files, `main` (the one loaded) and `side` (a file it names), each a
/// (name, bytes) pair: one case in four mutates `side`, the others `main`.
fn fuzz_pair(name: &str, main: (&str, &[u8]), side: (&str, &[u8])) {
    fuzz(name, 400, |rng, dir| {
        let mut files = [main.1.to_vec(), side.1.to_vec()];
        let k = usize::from(rng.below(4) == 0);
        mutate(rng, &mut files[k]);
        std::fs::write(dir.join(side.0), &files[1]).unwrap();
        std::fs::write(dir.join(main.0), &files[0]).unwrap();
        dir.join(main.0)
    });
}

/// The binary buffer of the glTF: 4 positions, 4 normals, 4 TEXCOORD_0, 4 TEXCOORD_1, 6 u16
/// indices (+2 bytes padding), 1 sparse u8 index (+3 padding) and its TEXCOORD_1 value.
fn gltf_bin() -> Vec<u8> {
    let mut b = Vec::new();
    let f = |b: &mut Vec<u8>, v: &[f32]| b.extend(v.iter().flat_map(|x| x.to_le_bytes()));
    f(&mut b, &[0., 0., 0., 1., 0., 0., 1., 0., 1., 0., 0., 1.]); // 0..48
    f(&mut b, &[0., 1., 0., 0., 1., 0., 0., 1., 0., 0., 1., 0.]); // 48..96
    f(&mut b, &[0., 0., 1., 0., 1., 1., 0., 1.]); // 96..128
    f(&mut b, &[0.1, 0.1, 0.4, 0.1, 0.4, 0.4, 0.1, 0.4]); // 128..160
    b.extend([0u16, 2, 1, 0, 3, 2, 0].iter().flat_map(|x| x.to_le_bytes())); // 160..174
    b.extend([2u8, 0, 0, 0]); // 174..178
    f(&mut b, &[0.45, 0.45]); // 178..186
    b.extend([0u8, 0]); // 188
    b
}

fn gltf_json(buffer: &str) -> String {
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "extensionsUsed": ["KHR_lights_punctual"],
  "extensions": {{"KHR_lights_punctual": {{"lights": [{{"type": "point", "color": [1, 1, 1], "intensity": 2}}]}}}},
  "buffers": [{buffer}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48, "byteStride": 12}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 96, "byteLength": 32}},
    {{"buffer": 0, "byteOffset": 128, "byteLength": 32}},
    {{"buffer": 0, "byteOffset": 160, "byteLength": 12}},
    {{"buffer": 0, "byteOffset": 174, "byteLength": 1}},
    {{"buffer": 0, "byteOffset": 178, "byteLength": 8}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0,0,0], "max": [1,0,1]}},
    {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"}},
    {{"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"}},
    {{"bufferView": 3, "componentType": 5126, "count": 4, "type": "VEC2",
      "sparse": {{"count": 1, "indices": {{"bufferView": 5, "componentType": 5121}}, "values": {{"bufferView": 6}}}}}},
    {{"bufferView": 4, "componentType": 5123, "count": 6, "type": "SCALAR"}}],
  "materials": [{{"name": "m", "pbrMetallicRoughness": {{"baseColorFactor": [0.2, 0.4, 0.6, 1]}}}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "TEXCOORD_1": 3}}, "indices": 4, "material": 0, "mode": 4}}]}}],
  "cameras": [{{"type": "perspective", "perspective": {{"yfov": 0.8, "znear": 0.01}}}}],
  "nodes": [
    {{"children": [1, 2], "translation": [0, 0, 1]}},
    {{"mesh": 0, "scale": [2, 2, 2]}},
    {{"camera": 0, "translation": [0, 1, 5]}},
    {{"extensions": {{"KHR_lights_punctual": {{"light": 0}}}}, "translation": [0, 3, 0]}}],
  "scenes": [{{"nodes": [0, 3]}}],
  "scene": 0
}}"#
    )
}

/// A GLB: header, JSON chunk, BIN chunk.
fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    prm_scene::export::glb_container(json.as_bytes(), bin).unwrap()
}

#[test]
fn fuzz_gltf_loader() {
    let bin = gltf_bin();
    let json = gltf_json(&format!(r#"{{"uri": "s.bin", "byteLength": {}}}"#, bin.len()));
    let base = temp_case("fuzz-gltf-base");
    std::fs::write(base.join("s.bin"), &bin).unwrap();
    std::fs::write(base.join("s.gltf"), &json).unwrap();
    let scene = prm_scene::load(&base.join("s.gltf")).expect("the unmutated glTF loads");
    assert_eq!(scene.triangles.len(), 2);
    assert!(scene.lightmap_uvs.is_some());
    fuzz_pair("gltf", ("s.gltf", json.as_bytes()), ("s.bin", &bin));
}

#[test]
fn fuzz_glb_loader() {
    let bin = gltf_bin();
    let json = gltf_json(&format!(r#"{{"byteLength": {}}}"#, bin.len()));
    let file = glb(&json, &bin);
    let base = temp_case("fuzz-glb-base");
    std::fs::write(base.join("s.glb"), &file).unwrap();
    let scene = prm_scene::load(&base.join("s.glb")).expect("the unmutated GLB loads");
    assert_eq!(scene.triangles.len(), 2);
    fuzz("glb", 400, |rng, dir| {
        // Mutate the JSON or the BIN chunk and rebuild consistent headers, or the raw file.
        let g = match rng.below(3) {
            0 => {
                let mut j = json.as_bytes().to_vec();
                mutate(rng, &mut j);
                glb(&String::from_utf8_lossy(&j), &bin)
            }
            1 => {
                let mut b = bin.clone();
                mutate(rng, &mut b);
                glb(&json, &b)
            }
            _ => {
                let mut g = file.clone();
                mutate(rng, &mut g);
                g
            }
        };
        std::fs::write(dir.join("s.glb"), &g).unwrap();
        dir.join("s.glb")
    });
}
