//! `prm-bake dump`: summarise, verify and export the panes of a `.prm` archive.

use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use prm_format::{compression, Archive, VerifyReport};
use serde_json::{json, Value};

/// Arguments of `prm-bake dump`.
#[derive(clap::Args, Debug, Clone)]
pub struct DumpArgs {
    /// The `.prm` archive to inspect.
    pub file: PathBuf,
    /// Print one JSON object (keys documented in formats/prm.md §10) instead
    /// of the readable summary.
    #[arg(long)]
    pub json: bool,
    /// Decompress everything and check every checksum; fails naming the
    /// damaged structure.
    #[arg(long)]
    pub verify: bool,
    /// Write one EXR per pane (pane_00000.exr, …) and overview.exr, all
    /// panes tiled in a grid, into DIR (created if missing).
    #[arg(long, value_name = "DIR")]
    pub export_exr: Option<PathBuf>,
}

/// Runs `prm-bake dump`.
pub fn run(args: &DumpArgs) -> Result<()> {
    if let Some(dir) = args.export_exr.as_ref().filter(|d| d.exists() && !d.is_dir()) {
        crate::refuse!(
            "--export-exr {}: it exists and is not a directory (--export-exr names the directory the EXR files go to)",
            dir.display()
        );
    }
    let mut archive =
        Archive::open(&args.file).with_context(|| format!("cannot open archive {}", args.file.display()))?;
    let report = if args.verify {
        Some(
            archive
                .verify()
                .with_context(|| format!("{} failed verification", args.file.display()))?,
        )
    } else {
        None
    };
    let printed = {
        let stdout = std::io::stdout();
        let mut out = stdout.lock();
        if args.json {
            let v = summary_json(&archive, &args.file, report.as_ref());
            serde_json::to_writer_pretty(&mut out, &v)
                .map_err(std::io::Error::from)
                .and_then(|()| writeln!(out))
        } else {
            write_summary(&mut out, &archive, &args.file, report.as_ref())
        }
        .and_then(|()| out.flush())
    };
    match printed {
        // e.g. `prm-bake dump x.prm | head`: not an error worth reporting
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {}
        r => r.context("cannot write to stdout")?,
    }
    if let Some(dir) = &args.export_exr {
        let n = export_exr(&mut archive, dir)?;
        eprintln!("wrote {n} pane EXR files and overview.exr to {}", dir.display());
    }
    Ok(())
}

/// What an archive needs resident on the GPU as the run time loads it by default: the panes'
/// basis rows that are not zero (`f16`, each tile's rank rounded up to four) and their
/// coefficients with the residual groups' (per tile a `u32` index entry per pane, and per pane
/// that is not zero there a scale word and a 4-byte word a rank, 8 bytes a word), and
/// the near field's exit records (8 bytes) and merged hits (4 bytes; twice where the deeper
/// share's disk differs from the direct share's), and the entry cells' points (8 bytes).
fn resident_line<R: Read + Seek>(archive: &Archive<R>) -> String {
    use prm_scene::MergeNearHits;
    let mib = |b: u64| b as f64 / (1024.0 * 1024.0);
    let basis = archive.pane_basis();
    let clusters = archive.pane_count();
    let groups = prm_format::residual_group_count(clusters, prm_format::RESIDUAL_GROUPS) as usize;
    let quads = |r: u32| u64::from(r).div_ceil(4);
    let rows: u64 = (0..basis.tile_count())
        .map(|t| basis.nonzero_rows(t).count() as u64 * quads(basis.ranks()[t]) * 8)
        .sum();
    let group_of = prm_format::residual_groups(archive.clusters(), groups as u32);
    let coefficients: u64 = (0..basis.tile_count())
        .filter(|&t| basis.ranks()[t] > 0)
        .map(|t| {
            let mut lit = vec![false; clusters + groups];
            for c in (0..clusters).filter(|&c| !basis.block_is_zero(c, t)) {
                lit[c] = true;
                match group_of.get(c) {
                    Some(&g) if (g as usize) < groups => lit[clusters + g as usize] = true,
                    _ => {}
                }
            }
            let blocks = lit.iter().filter(|&&l| l).count() as u64;
            8 * (clusters + groups).div_ceil(2) as u64 + blocks * 8 * (1 + 2 * quads(basis.ranks()[t]))
        })
        .sum();
    let near = archive.near_field().map_or(0, |n| {
        let (_, merged) = n.merged_hits();
        let sets = if n.indirect_disk > 0.0 && n.indirect_disk != n.disk {
            2
        } else {
            1
        };
        (8 * n.exits.len() + 4 * sets * merged.len()) as u64
    });
    let cells = archive.entry_cells().map_or(0, |c| 8 * c.points.len() as u64);
    format!(
        "{:.1} MiB on the GPU: panes {:.1} MiB (basis {:.1} MiB, coefficients of {clusters} clusters + {groups} \
         residual groups {:.1} MiB), near field {:.1} MiB, entry cells {:.1} MiB",
        mib(rows + coefficients + near + cells),
        mib(rows + coefficients),
        mib(rows),
        mib(coefficients),
        mib(near),
        mib(cells)
    )
}

fn hex(v: u64) -> String {
    format!("{v:016x}")
}

fn human_bytes(n: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = n as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{n} B")
    } else {
        format!("{v:.2} {}", UNITS[u])
    }
}

/// Five significant digits, fixed-point where readable.
fn num(v: f32) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if (1e-3..1e6).contains(&a) {
        let decimals = (4 - a.log10().floor() as i32).max(0) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.4e}")
    }
}

fn ratio(raw: u64, stored: u64) -> f64 {
    if stored == 0 {
        0.0
    } else {
        raw as f64 / stored as f64
    }
}

/// The `--json` object (formats/prm.md §10).
pub fn summary_json<R: Read + Seek>(archive: &Archive<R>, file: &Path, report: Option<&VerifyReport>) -> Value {
    let info = archive.info();
    let meta = archive.metadata();
    let atlas = archive.atlas();
    let sections: Vec<Value> = info
        .sections
        .iter()
        .map(|s| {
            json!({
                "kind": s.kind,
                "name": s.name,
                "compression": compression::name(s.compression),
                "offset": s.offset,
                "stored_size": s.stored_size,
                "raw_size": s.raw_size,
                "checksum": hex(s.checksum),
            })
        })
        .collect();
    let panes: Vec<Value> = archive
        .clusters()
        .iter()
        .enumerate()
        .map(|(i, c)| json!({"index": i, "entries": c.count, "energy": c.energy, "peak": c.peak}))
        .collect();
    let panes_stored = info
        .sections
        .iter()
        .find(|s| s.kind == prm_format::kind::PANES)
        .map_or(0, |s| s.stored_size);
    let mut v = json!({
        "file": file.display().to_string(),
        "version": format!("{}.{}", info.major, info.minor),
        "file_length": info.file_length,
        "sections": sections,
        "generator": meta.generator,
        "params": meta.params,
        "seed": meta.seed,
        "timings": meta.timings,
        "units": meta.units,
        "source_scene": meta.source_scene,
        "scene_fingerprint": hex(meta.scene_fingerprint),
        "texel_encoding": meta.texel_encoding,
        "texel_relative_error_bound": meta.texel_relative_error_bound,
        "resolution": atlas.resolution,
        "tile_size": atlas.tile_size,
        "triangles": atlas.triangle_uvs.len(),
        "covered_texels": atlas.covered_texels(),
        "entries": archive.entries().len(),
        "entry_energy": archive.entry_energy().is_some(),
        "entry_cell_points": archive.entry_cells().map(|c| c.points.len()),
        "emitters": archive.emitters().iter().map(|g| json!({
            "name": g.name,
            "material": g.material,
            "radiance": g.radiance,
            "entry_irradiance_sum": rgb_sum(&g.entry_irradiance),
            "direct_sum": rgb_sum(&g.direct),
            "indirect_sum": g.indirect.as_deref().map(rgb_sum),
        })).collect::<Vec<_>>(),
        "sky": archive.sky().map(|s| {
            let (d, i) = uniform_sky_sums(s);
            json!({"coefficients": prm_format::SH_COEFFS, "unit_uniform_direct_sum": d, "unit_uniform_indirect_sum": i})
        }),
        "probes": archive.probes().map(|p| json!({
            "count": p.len(),
            "grid": p.grid.dims,
            "origin": p.grid.origin,
            "spacing": p.grid.spacing,
            "coefficients": prm_format::SH_COEFFS,
            "unit_weight_mean_irradiance": probe_mean_irradiance(p),
            "sky": p.sky.is_some(),
            "rays": archive.probe_rays().map(|r| {
                let [texels, sky, blocked] = ray_shares(r);
                json!({
                    "rays_per_probe": r.rays_per_probe,
                    "gather_points": r.points.len(),
                    "to_texels": texels,
                    "to_sky": sky,
                    "blocked": blocked,
                })
            }),
        })),
        "near_field": archive.near_field().map(|n| json!({
            "rays_per_exit": n.rays_per_exit,
            "disk_radius": n.disk.sqrt(),
            "indirect_disk_radius": n.indirect_disk.sqrt(),
            "complement": n.complement,
            "exit_points": n.exits.len(),
            "gather_points": n.points.len(),
            "hits": n.hits.len(),
        })),
        "accuracy": meta.accuracy.as_ref().map(|a| json!({
            "exit_points": a.exit_points,
            "paths": a.paths,
            "top_k": a.top_k,
            "residual_groups": a.residual_groups,
            "mean_error": a.mean_error(),
            "mean_error_all_clusters": a.mean_error_all_clusters(),
            "mean_energy": a.mean_energy(),
            "mean_standard_error": a.mean_standard_error(),
            "lights": a.lights,
        })),
        "clusters": archive.clusters().len(),
        "basis": {
            "tiles": info.tiles,
            "ranks": archive.pane_basis().ranks(),
            "max_rank": info.max_rank,
            "mean_rank": info.rank_sum as f64 / info.tiles.max(1) as f64,
            "basis_bytes": info.basis_bytes,
            "coefficient_bytes": info.coefficient_bytes,
            "stored_bytes": panes_stored,
            "texel_bytes": info.pane_texel_bytes,
        },
        "panes": panes,
    });
    if let Some(r) = report {
        v["verify"] = json!({
            "ok": true,
            "sections": r.sections,
            "panes": r.panes,
            "bytes_hashed": r.bytes_hashed,
        });
    }
    v
}

/// The readable summary.
pub fn write_summary<W: Write, R: Read + Seek>(
    out: &mut W,
    archive: &Archive<R>,
    file: &Path,
    report: Option<&VerifyReport>,
) -> std::io::Result<()> {
    let info = archive.info();
    let meta = archive.metadata();
    let atlas = archive.atlas();
    let texels = u64::from(atlas.resolution) * u64::from(atlas.resolution);
    let covered = atlas.covered_texels();
    writeln!(out, "archive      {}", file.display())?;
    writeln!(
        out,
        "format       .prm {}.{}, {} ({} bytes)",
        info.major,
        info.minor,
        human_bytes(info.file_length),
        info.file_length
    )?;
    writeln!(out, "generator    {} {}", meta.generator.name, meta.generator.version)?;
    writeln!(
        out,
        "scene        {} (fingerprint {})",
        if meta.source_scene.is_empty() {
            "-"
        } else {
            &meta.source_scene
        },
        hex(meta.scene_fingerprint)
    )?;
    writeln!(out, "seed         {}", meta.seed)?;
    if let Some(b) = meta.params.get("backend").and_then(|b| b.as_str()) {
        writeln!(out, "renderer     {b}")?;
    }
    match prm_bake::Shard::of(meta) {
        Some(Ok(shard)) => writeln!(
            out,
            "shard        {shard}: a partial archive (the other shards' panes are zero); join the parts with `prm-bake merge`"
        )?,
        Some(Err(e)) => writeln!(out, "shard        malformed: {e}")?,
        None => {}
    }
    writeln!(
        out,
        "units        length {}, irradiance {}",
        meta.units.length, meta.units.irradiance
    )?;
    writeln!(
        out,
        "encoding     {} (largest-channel relative error <= {:.3e})",
        meta.texel_encoding, meta.texel_relative_error_bound
    )?;
    writeln!(
        out,
        "atlas        {r}x{r} texels, tiles {t}x{t} ({} in all), {} triangles, {covered} covered texels ({:.1}%)",
        info.tiles,
        atlas.triangle_uvs.len(),
        100.0 * covered as f64 / texels.max(1) as f64,
        r = atlas.resolution,
        t = atlas.tile_size,
    )?;
    writeln!(out, "resident     {}", resident_line(archive))?;
    writeln!(
        out,
        "entries      {}{}{}",
        archive.entries().len(),
        if archive.entry_energy().is_some() {
            " (with pane energies: cluster weights weigh members by them)"
        } else {
            " (no pane energies: cluster weights are the members' mean; re-bake to weigh them)"
        },
        match archive.entry_cells() {
            Some(c) => format!(", lit over their cells' {} points", c.points.len()),
            None => ", each lit at its own point (no entry cells: re-bake to light them over their cells)".to_string(),
        }
    )?;
    write_contents(out, archive)?;
    write_sections(out, archive)?;
    write_parameters(out, archive)?;
    write_panes(out, archive)?;
    if let Some(r) = report {
        writeln!(
            out,
            "\nverify       OK: {} sections ({}) hashed, {} panes decoded, cluster energy/peak match",
            r.sections,
            human_bytes(r.bytes_hashed),
            r.panes,
        )?;
    }
    Ok(())
}

/// The optional sections' lines: emitters, sky, probes, near field, clusters and the accuracy estimate.
fn write_contents<W: Write, R: Read + Seek>(out: &mut W, archive: &Archive<R>) -> std::io::Result<()> {
    let meta = archive.metadata();
    for g in archive.emitters() {
        let [r, gr, b] = g.radiance;
        let [er, eg, eb] = rgb_sum(&g.direct);
        let indirect = match g.indirect.as_deref().map(rgb_sum) {
            Some([ir, ig, ib]) => format!("indirect {ir:.1} {ig:.1} {ib:.1} (traced)"),
            None => "indirect through the panes".to_string(),
        };
        writeln!(
            out,
            "emitter      {:?} (material {}): radiance {r:.3} {gr:.3} {b:.3}; irradiance summed over the atlas: direct {er:.1} {eg:.1} {eb:.1}, {indirect}",
            g.name, g.material
        )?;
    }
    if let Some(s) = archive.sky() {
        let ([dr, _, _], [ir, ig, ib]) = uniform_sky_sums(s);
        writeln!(
            out,
            "sky          transfer in {} spherical-harmonic coefficients per texel; a uniform sky of radiance 1 gives, summed over the atlas: direct {dr:.1}, indirect {ir:.1} {ig:.1} {ib:.1}",
            prm_format::SH_COEFFS
        )?;
    }
    if let Some(p) = archive.probes() {
        let [r, g, b] = probe_mean_irradiance(p);
        writeln!(
            out,
            "probes       {} on a {}×{}×{} grid of {:.3} from ({:.3}, {:.3}, {:.3}), {} spherical-harmonic coefficients per cluster; unit weights give a probe {r:.3} {g:.3} {b:.3} on average (mean over six axis normals){}",
            p.len(),
            p.grid.dims[0],
            p.grid.dims[1],
            p.grid.dims[2],
            p.grid.spacing,
            p.grid.origin[0],
            p.grid.origin[1],
            p.grid.origin[2],
            prm_format::SH_COEFFS,
            if p.sky.is_some() {
                "; with the sky's transfer to them"
            } else {
                ""
            }
        )?;
        if let Some(r) = archive.probe_rays() {
            let [texels, sky, blocked] = ray_shares(r);
            writeln!(
                out,
                "probe rays   {} per probe, ending at {} texels: {:.1}% reach a texel, {:.1}% the sky, {:.1}% nothing; the player gathers the probes' light along them",
                r.rays_per_probe,
                r.points.len(),
                100.0 * texels,
                100.0 * sky,
                100.0 * blocked
            )?;
        }
    }
    if let Some(n) = archive.near_field() {
        writeln!(
            out,
            "near field   {} texels keep {} rays in all ({} traced per exit point, VPL disk radius {:.4}, deeper VPLs' {}{}), ending at {} texels; the player gathers back there what the VPL bound removes",
            n.exits.len(),
            n.hits.len(),
            n.rays_per_exit,
            n.disk.sqrt(),
            if n.indirect_disk > 0.0 {
                format!("{:.4}", n.indirect_disk.sqrt())
            } else {
                "not gathered".to_string()
            },
            if n.complement {
                ", weights complement the panes' kernel"
            } else {
                ""
            },
            n.points.len()
        )?;
    }
    writeln!(out, "clusters     {} (one pane each)", archive.clusters().len())?;
    match &meta.accuracy {
        None => writeln!(out, "accuracy     not estimated by the bake")?,
        Some(a) => write_accuracy(out, "accuracy     ", a)?,
    }
    Ok(())
}

/// The section table and the panes' basis.
fn write_sections<W: Write, R: Read + Seek>(out: &mut W, archive: &Archive<R>) -> std::io::Result<()> {
    let info = archive.info();
    writeln!(out, "\nsections")?;
    let w = info.sections.iter().map(|s| s.name.len()).max().unwrap_or(0).max(8);
    writeln!(
        out,
        "  {:<w$} {:<6} {:>12} {:>12} {:>12} {:>8}  checksum",
        "name", "codec", "offset", "stored", "raw", "ratio"
    )?;
    for s in &info.sections {
        writeln!(
            out,
            "  {:<w$} {:<6} {:>12} {:>12} {:>12} {:>8.2}  {}",
            s.name,
            compression::name(s.compression),
            s.offset,
            s.stored_size,
            s.raw_size,
            ratio(s.raw_size, s.stored_size),
            hex(s.checksum)
        )?;
    }
    writeln!(
        out,
        "  panes: a basis per tile, mean rank {:.1} (largest {}) over {} tiles: {} of f16 basis and {} of coefficients, for {} of RGB9E5 texels (ratio {:.2})",
        info.rank_sum as f64 / info.tiles.max(1) as f64,
        info.max_rank,
        info.tiles,
        human_bytes(info.basis_bytes),
        human_bytes(info.coefficient_bytes),
        human_bytes(info.pane_texel_bytes),
        ratio(info.pane_texel_bytes, info.basis_bytes + info.coefficient_bytes)
    )?;
    Ok(())
}

/// The bake parameters and timings the metadata records.
fn write_parameters<W: Write, R: Read + Seek>(out: &mut W, archive: &Archive<R>) -> std::io::Result<()> {
    let meta = archive.metadata();
    writeln!(out, "\nbake parameters")?;
    if meta.params.is_empty() {
        writeln!(out, "  (none)")?;
    }
    for (k, v) in &meta.params {
        writeln!(out, "  {k} = {v}")?;
    }
    writeln!(out, "\ntimings")?;
    if meta.timings.is_empty() {
        writeln!(out, "  (none)")?;
    }
    let mut total = 0.0;
    for (k, v) in &meta.timings {
        writeln!(out, "  {k:<20} {v:>10.3} s")?;
        total += v;
    }
    if meta.timings.len() > 1 {
        writeln!(out, "  {:<20} {total:>10.3} s", "(sum)")?;
    }
    Ok(())
}

/// One line per pane: its cluster's size, energy and peak.
fn write_panes<W: Write, R: Read + Seek>(out: &mut W, archive: &Archive<R>) -> std::io::Result<()> {
    writeln!(out, "\npanes")?;
    writeln!(
        out,
        "  {:>6} {:>7}  {:>32}  {:>32}",
        "pane", "entries", "energy (r g b)", "peak (r g b)"
    )?;
    for (i, c) in archive.clusters().iter().enumerate() {
        let e = c.energy.map(num);
        let p = c.peak.map(num);
        writeln!(
            out,
            "  {i:>6} {:>7}  {:>10} {:>10} {:>10}  {:>10} {:>10} {:>10}",
            c.count, e[0], e[1], e[2], p[0], p[1], p[2]
        )?;
    }
    Ok(())
}

/// Largest side of the overview image, in pixels.
const OVERVIEW_MAX_SIDE: usize = 4096;

/// Writes `pane_NNNNN.exr` for every pane and `overview.exr` with all panes
/// in a grid (each cell box-filtered down so the overview's width stays
/// within 4096 pixels). Returns the number of panes written.
///
/// All or nothing: the files are written into a staging directory inside `dir` and moved into
/// place only once every pane has been read, so a damaged archive leaves no partial export (and
/// a `dir` this call created is removed again).
pub fn export_exr<R: Read + Seek>(archive: &mut Archive<R>, dir: &Path) -> Result<usize> {
    let created = !dir.exists();
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let staging = dir.join(format!(".prm-export-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&staging);
    std::fs::create_dir(&staging).with_context(|| format!("cannot create {}", staging.display()))?;
    let written = write_exr_files(archive, &staging).and_then(|(n, names)| {
        for name in &names {
            std::fs::rename(staging.join(name), dir.join(name))
                .with_context(|| format!("cannot move {name} into {}", dir.display()))?;
        }
        Ok(n)
    });
    let _ = std::fs::remove_dir_all(&staging);
    if written.is_err() && created {
        let _ = std::fs::remove_dir(dir);
    }
    written
}

/// [`export_exr`]'s files, written into `dir`; returns the pane count and the file names.
fn write_exr_files<R: Read + Seek>(archive: &mut Archive<R>, dir: &Path) -> Result<(usize, Vec<String>)> {
    let mut names = Vec::new();
    let res = archive.atlas().resolution as usize;
    let n = archive.pane_count();
    let cols = (n as f64).sqrt().ceil().max(1.0) as usize;
    let rows = n.div_ceil(cols).max(1);
    let cell = res.min((OVERVIEW_MAX_SIDE / cols).max(1));
    let (width, height) = (cols * cell, rows * cell);
    let mut overview = vec![[0f32; 3]; width * height];
    for p in 0..n {
        let pane = archive.read_pane(p).with_context(|| format!("cannot read pane {p}"))?;
        let name = format!("pane_{p:05}.exr");
        let path = dir.join(&name);
        names.push(name);
        exr::prelude::write_rgb_file(&path, res, res, |x, y| {
            let t = pane[y * res + x];
            (t[0], t[1], t[2])
        })
        .with_context(|| format!("cannot write {}", path.display()))?;
        let (ox, oy) = ((p % cols) * cell, (p / cols) * cell);
        for v in 0..cell {
            let (y0, y1) = (v * res / cell, ((v + 1) * res / cell).max(v * res / cell + 1));
            for u in 0..cell {
                let (x0, x1) = (u * res / cell, ((u + 1) * res / cell).max(u * res / cell + 1));
                let mut sum = [0f64; 3];
                for y in y0..y1 {
                    for t in &pane[y * res + x0..y * res + x1] {
                        for c in 0..3 {
                            sum[c] += f64::from(t[c]);
                        }
                    }
                }
                let k = ((y1 - y0) * (x1 - x0)) as f64;
                overview[(oy + v) * width + ox + u] = sum.map(|s| (s / k) as f32);
            }
        }
    }
    if n > 0 {
        let path = dir.join("overview.exr");
        exr::prelude::write_rgb_file(&path, width, height, |x, y| {
            let t = overview[y * width + x];
            (t[0], t[1], t[2])
        })
        .with_context(|| format!("cannot write {}", path.display()))?;
        names.push("overview.exr".to_string());
    }
    Ok((n, names))
}

/// The shares of the probe rays that reach a texel, the sky and nothing.
fn ray_shares(r: &prm_format::ProbeRays) -> [f64; 3] {
    let n = r.hits.len().max(1) as f64;
    let count = |code: u32| r.hits.iter().filter(|&&h| h == code).count() as f64 / n;
    let (sky, blocked) = (count(prm_format::RAY_SKY), count(prm_format::RAY_BLOCKED));
    [1.0 - sky - blocked, sky, blocked]
}

/// A probe's indirect irradiance with every cluster's weight 1, averaged over the probes and
/// the six axis normals: a scale to compare bakes by.
fn probe_mean_irradiance(p: &prm_format::Probes) -> [f64; 3] {
    let sh = p.irradiance_sh(&vec![[1.0; 3]; p.clusters()]);
    let mut sum = [0.0f64; 3];
    for c in &sh {
        for n in prm_format::AXIS_NORMALS {
            let e = prm_format::sh_irradiance(c, n);
            for k in 0..3 {
                sum[k] += f64::from(e[k]);
            }
        }
    }
    sum.map(|s| s / (6 * p.len().max(1)) as f64)
}

/// The sky's direct and indirect irradiance summed over the atlas under a uniform sky of
/// radiance 1 (only the constant coefficient, `2√π`, is non-zero).
fn uniform_sky_sums(s: &prm_format::SkyTransfer) -> ([f64; 3], [f64; 3]) {
    let mut unit = [[0.0f32; 3]; prm_format::SH_COEFFS];
    unit[0] = [2.0 * std::f32::consts::PI.sqrt(); 3];
    let (mut d, mut i) = (Vec::new(), Vec::new());
    for t in 0..s.direct.len() {
        let (a, b) = s.irradiance(t, &unit);
        d.push(a);
        i.push(b);
    }
    (rgb_sum(&d), rgb_sum(&i))
}

/// Per-channel sum of RGB values (f64 accumulation).
fn rgb_sum(v: &[[f32; 3]]) -> [f64; 3] {
    v.iter()
        .fold([0.0; 3], |s, x| [0, 1, 2].map(|k| s[k] + f64::from(x[k])))
}

/// An accuracy estimate as `dump` and `check` print it: the line `prm_bake::accuracy_line`
/// gives after `lead`, then one line per light.
pub(crate) fn write_accuracy(out: &mut impl Write, lead: &str, a: &prm_format::Accuracy) -> std::io::Result<()> {
    writeln!(out, "{lead}{}", prm_bake::accuracy_line(a))?;
    for l in &a.lights {
        writeln!(
            out,
            "{:w$}light at ({:.3}, {:.3}, {:.3}): {:.1}% ± {:.1} (measured {:.1}%, K = all {:.1}%), energy {:.3}",
            "",
            l.position[0],
            l.position[1],
            l.position[2],
            100.0 * l.error,
            100.0 * l.standard_error,
            100.0 * l.measured,
            100.0 * l.error_all_clusters,
            l.energy,
            w = lead.chars().count() + 2,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use prm_format::{ArchiveWriter, AtlasSection, Cluster, Entry, Metadata};

    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("prm-bake-dump-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A copy of the archive at `path` with its last stored tile damaged, written to `bad`.
    fn damage_last_tile(path: &Path, bad: &Path) -> PathBuf {
        let mut bytes = std::fs::read(path).unwrap();
        let a = Archive::open(path).unwrap();
        let panes = a.info().sections.iter().find(|s| s.name == "panes").unwrap();
        let at = (panes.offset + panes.stored_size - 3) as usize;
        bytes[at] ^= 0x40;
        std::fs::write(bad, &bytes).unwrap();
        bad.to_path_buf()
    }

    /// A fresh scratch directory `name` holding the archive of [`write_archive`] as `a.prm`:
    /// (directory, archive).
    fn scratch_archive(name: &str) -> (PathBuf, PathBuf) {
        let dir = temp_dir(name);
        let path = dir.join("a.prm");
        write_archive(&path);
        (dir, path)
    }

    fn write_archive(path: &Path) {
        write_archive_with(path, None);
    }

    fn write_archive_with(path: &Path, accuracy: Option<prm_format::Accuracy>) {
        let mut meta = Metadata::new("dump-test", "1.0");
        meta.accuracy = accuracy;
        meta.params.insert("bounces".into(), 2.into());
        meta.timings.insert("trace".into(), 3.5);
        meta.timings.insert("compress".into(), 0.25);
        meta.scene_fingerprint = 0xfeed;
        let atlas = AtlasSection::new(8, 4);
        let entries = vec![
            Entry {
                position: [0.0; 3],
                normal: [0.0, 0.0, 1.0],
                cluster: 0,
            },
            Entry {
                position: [1.0; 3],
                normal: [0.0, 0.0, 1.0],
                cluster: 1,
            },
        ];
        let clusters = vec![
            Cluster::new(0, 1, [0.0; 3], [0.0, 0.0, 1.0]),
            Cluster::new(1, 1, [1.0; 3], [0.0, 0.0, 1.0]),
            Cluster::new(2, 0, [0.0; 3], [0.0, 0.0, 1.0]),
        ];
        let mut w = ArchiveWriter::create(path, meta, &atlas, &entries, &clusters).unwrap();
        for p in 0..3 {
            // Lit in every other 4² tile of the 8² atlas.
            let pane: Vec<[f32; 3]> = (0..64)
                .map(|i| match ((i % 8) / 4 + (i / 8) / 4) % 2 {
                    0 => [p as f32, 0.5, 0.25],
                    _ => [0.0; 3],
                })
                .collect();
            w.add_pane(&pane).unwrap();
        }
        w.finish().unwrap();
    }

    #[test]
    fn numbers_are_readable() {
        assert_eq!(num(0.0), "0");
        assert_eq!(num(1.0), "1.0000");
        assert_eq!(num(31.511), "31.511");
        assert_eq!(num(70960.0), "70960");
        assert_eq!(num(0.0012345), "0.0012345");
        assert_eq!(num(2.5e7), "2.5000e7");
        assert_eq!(num(1e-5), "1.0000e-5");
    }

    #[test]
    fn json_summary_has_documented_keys() {
        let (dir, path) = scratch_archive("json");
        let mut a = Archive::open(&path).unwrap();
        let report = a.verify().unwrap();
        let v = summary_json(&a, &path, Some(&report));
        assert_eq!(v["version"], "2.0");
        assert_eq!(v["entries"], 2);
        assert_eq!(v["clusters"], 3);
        assert_eq!(v["resolution"], 8);
        assert_eq!(v["sections"].as_array().unwrap().len(), 5);
        assert_eq!(v["params"]["bounces"], 2);
        assert_eq!(v["timings"]["trace"], 3.5);
        assert_eq!(v["scene_fingerprint"], "000000000000feed");
        // Two of the four tiles lit, each pane one colour there: rank 1 where lit.
        assert_eq!(v["basis"]["tiles"], 4);
        assert_eq!(v["basis"]["ranks"], serde_json::json!([1, 0, 0, 1]));
        assert_eq!(v["panes"][1]["peak"][0], 1.0);
        assert_eq!(v["verify"]["panes"], 3);

        let mut text = Vec::new();
        write_summary(&mut text, &a, &path, Some(&report)).unwrap();
        let text = String::from_utf8(text).unwrap();
        for needle in [
            "format       .prm 2.0",
            "bounces = 2",
            "trace",
            "clusters     3",
            "verify       OK",
        ] {
            assert!(text.contains(needle), "missing {needle:?} in\n{text}");
        }
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn the_bake_s_accuracy_estimate_is_shown() {
        let dir = temp_dir("accuracy");
        let path = dir.join("a.prm");
        let light = prm_format::LightAccuracy {
            position: [0.5, 1.5, 0.0],
            error: 0.125,
            measured: 0.15,
            reference_noise: 0.08,
            energy: 0.96,
            error_all_clusters: 0.1,
            standard_error: 0.02,
        };
        write_archive_with(
            &path,
            Some(prm_format::Accuracy {
                exit_points: 256,
                paths: 256,
                top_k: 32,
                residual_groups: 4,
                lights: vec![light],
            }),
        );
        let a = Archive::open(&path).unwrap();
        let v = summary_json(&a, &path, None);
        assert_eq!(v["version"], "2.0");
        assert_eq!(v["accuracy"]["mean_error"], 0.125);
        assert_eq!(v["accuracy"]["lights"][0]["energy"], 0.96);
        let mut text = Vec::new();
        write_summary(&mut text, &a, &path, None).unwrap();
        let text = String::from_utf8(text).unwrap();
        for needle in [
            "12.5% ± 2.0 off the reference (K = all: 10.0%), energy 0.960",
            "light at (0.500, 1.500, 0.000): 12.5% ± 2.0 (measured 15.0%",
        ] {
            assert!(
                text.contains(needle),
                "missing {needle:?} in
{text}"
            );
        }
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn verify_names_the_damage() {
        let (dir, path) = scratch_archive("verify");
        let bad = damage_last_tile(&path, &dir.join("bad.prm"));
        let args = DumpArgs {
            file: bad.clone(),
            json: true,
            verify: true,
            export_exr: None,
        };
        let err = format!("{:#}", run(&args).unwrap_err());
        // The panes are read whole when the archive opens: the damage is named there.
        assert!(err.contains("checksum mismatch in panes"), "{err}");
        let missing = DumpArgs {
            file: dir.join("missing.prm"),
            ..args
        };
        assert!(format!("{:#}", run(&missing).unwrap_err()).contains("cannot open archive"));
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn export_of_a_damaged_archive_leaves_nothing_behind() {
        let (dir, path) = scratch_archive("exr-damaged");
        let bad = damage_last_tile(&path, &dir.join("bad.prm"));
        let out = dir.join("exr");
        let args = DumpArgs {
            file: bad,
            json: false,
            verify: false,
            export_exr: Some(out.clone()),
        };
        let err = format!("{:#}", run(&args).unwrap_err());
        assert!(err.contains("cannot open archive"), "{err}");
        assert!(!out.exists(), "a failed export left {}", out.display());
        // Into an existing directory: its other files stay, no pane file appears.
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(out.join("keep.txt"), "x").unwrap();
        assert!(run(&args).is_err());
        let left: Vec<_> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(left, vec![std::ffi::OsString::from("keep.txt")]);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn exports_one_exr_per_pane_and_an_overview() {
        let (dir, path) = scratch_archive("exr");
        let out = dir.join("exr");
        let mut a = Archive::open(&path).unwrap();
        assert_eq!(export_exr(&mut a, &out).unwrap(), 3);
        for f in ["pane_00000.exr", "pane_00001.exr", "pane_00002.exr", "overview.exr"] {
            assert!(out.join(f).metadata().unwrap().len() > 0, "{f}");
        }
        std::fs::remove_dir_all(dir).unwrap();
    }
}
