//! Tests of the library call `prm_bake::bake`: a tiny CPU bake of the Cornell box reports its
//! phases in order, yields an archive with the planned counts, and is byte-identical when repeated.

use prm_bake::{BakeConfig, BakeError, BakeJob, Phase, Plan, ProgressSink, Renderer};
use prm_format::Archive;
use std::path::PathBuf;

mod common;
use common::{scene_path, STEPS};

/// What a [`ProgressSink`] was told.
#[derive(Debug, PartialEq)]
enum Event {
    Start(Phase, u64),
    Advance(u64),
    Finish(Phase),
    Info,
    Warn,
}

/// Records every event.
#[derive(Default)]
struct Recorder(Vec<Event>);

impl ProgressSink for Recorder {
    fn phase_start(&mut self, phase: Phase, total: u64) {
        self.0.push(Event::Start(phase, total));
    }
    fn phase_advance(&mut self, done: u64) {
        self.0.push(Event::Advance(done));
    }
    fn phase_finish(&mut self, phase: Phase, summary: &str, seconds: f64) {
        assert!(!summary.is_empty() && seconds >= 0.0, "{phase}: {summary:?} {seconds}");
        self.0.push(Event::Finish(phase));
    }
    fn info(&mut self, _: &str) {
        self.0.push(Event::Info);
    }
    fn warn(&mut self, _: &str) {
        self.0.push(Event::Warn);
    }
}

/// A fresh, empty directory for one test under the cargo-provided temporary directory.
fn temp_dir(name: &str) -> PathBuf {
    common::scratch_dir("prm-bake-library", name)
}

fn tiny() -> BakeConfig {
    BakeConfig {
        entries: Some(64),
        clusters: Some(8),
        resolution: Some(32),
        paths_per_entry: Some(1),
        face_resolution: Some(64),
        seed: Some(1),
        ..Default::default()
    }
}

#[test]
fn a_cpu_bake_reports_its_phases_and_writes_the_planned_archive() {
    let dir = temp_dir("cpu");
    let path = scene_path();
    let scene = prm_scene::load(&path).unwrap();
    let plan = Plan::new(&tiny(), &scene).unwrap();
    let out = dir.join("nested/a.prm");
    let job = BakeJob {
        scene: &scene,
        scene_path: &path,
        plan: &plan,
        output: &out,
        shard: None,
    };
    let mut recorder = Recorder::default();
    let baked = prm_bake::bake(&job, Renderer::Cpu, &mut recorder).unwrap();

    // Phases in order, each started and finished once, advancing up to its total.
    let phases: Vec<Phase> = recorder
        .0
        .iter()
        .filter_map(|e| match e {
            Event::Start(p, _) => Some(*p),
            _ => None,
        })
        .collect();
    assert_eq!(
        phases,
        [
            Phase::Atlas,
            Phase::Bvh,
            Phase::LightTracing,
            Phase::Clustering,
            Phase::NearField,
            Phase::PaneRendering,
            Phase::AccuracyCheck
        ]
    );
    let mut current = None;
    let mut done = 0;
    for e in &recorder.0 {
        match *e {
            Event::Start(p, total) => {
                assert_eq!(current, None, "{p} starts inside another phase: {:?}", recorder.0);
                current = Some((p, total));
                done = 0;
            }
            Event::Advance(d) => {
                let (p, total) = current.expect("an advance outside a phase");
                assert!(d >= done && d <= total, "{p}: {d} after {done} of {total}");
                done = d;
            }
            Event::Finish(p) => {
                assert_eq!(current.map(|c| c.0), Some(p), "{:?}", recorder.0);
                if p == Phase::PaneRendering {
                    // The CPU renderers count exit points.
                    let total = current.map_or(0, |c| c.1);
                    assert_eq!(total, baked.atlas.covered_texels as u64, "{:?}", recorder.0);
                    assert_eq!(done, total, "every exit point was reported");
                }
                current = None;
            }
            Event::Info | Event::Warn => {}
        }
    }
    assert_eq!(current, None);

    // The archive opens, verifies and has the planned counts.
    let mut archive = Archive::open(&out).expect("archive opens");
    archive.verify().expect("archive verifies");
    assert_eq!(archive.entries().len(), plan.params.entries);
    assert_eq!(archive.clusters().len(), plan.params.clusters);
    assert_eq!((baked.entries, baked.clusters), (64, 8));
    assert_eq!(archive.pane_count(), baked.clusters);
    assert_eq!(archive.atlas().resolution, 32);
    assert_eq!(archive.metadata().params["backend"], "cpu");
    assert_eq!(baked.archive_bytes, std::fs::metadata(&out).unwrap().len());
    for key in STEPS {
        assert!(
            baked.timings.get(key).is_some_and(|t| *t >= 0.0),
            "{key}: {:?}",
            baked.timings
        );
    }

    // The same inputs again: the same bytes.
    let again = dir.join("nested/b.prm");
    let job = BakeJob { output: &again, ..job };
    prm_bake::bake(&job, Renderer::Cpu, &mut prm_bake::NoProgress).unwrap();
    assert!(
        std::fs::read(&out).unwrap() == std::fs::read(&again).unwrap(),
        "two bakes of the same inputs differ"
    );
}

#[test]
fn impossible_parameters_and_destinations_are_typed_errors() {
    let scene = prm_scene::load(&scene_path()).unwrap();
    let too_many = BakeConfig {
        clusters: Some(100),
        ..tiny()
    };
    let e = Plan::new(&too_many, &scene).unwrap_err();
    assert!(matches!(e, BakeError::InvalidParams(_)), "{e:?}");
    assert!(e.to_string().contains("more clusters"), "{e}");

    // A directory as the output: refused before any work, nothing created.
    let dir = temp_dir("destination");
    let plan = Plan::new(&tiny(), &scene).unwrap();
    let path = scene_path();
    let job = BakeJob {
        scene: &scene,
        scene_path: &path,
        plan: &plan,
        output: &dir,
        shard: None,
    };
    let e = prm_bake::bake(&job, Renderer::Cpu, &mut prm_bake::NoProgress).unwrap_err();
    assert!(matches!(e, BakeError::Destination(_)), "{e:?}");
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
}

/// `sky` without `sky_paths` takes the sky's paths from what the time budget leaves: the most
/// the rule gives under the default budget on the small Cornell box, the fewest under a budget
/// the panes already fill; given paths stay as given.
#[test]
fn the_sky_paths_come_from_the_time_budget_unless_given() {
    let scene = prm_scene::load(&scene_path()).unwrap();
    let paths = |time_budget_s: Option<f64>, sky_paths: Option<u32>| {
        let config = BakeConfig {
            sky: Some(true),
            sky_paths,
            time_budget_s,
            ..BakeConfig::default()
        };
        Plan::new(&config, &scene).unwrap().params.sky_paths
    };
    assert_eq!(paths(None, None), Some(prm_bake::params::MAX_AUTO_SKY_PATHS));
    let plan = Plan::new(&BakeConfig::default(), &scene).unwrap().params;
    assert_eq!(plan.sky_paths, None, "no sky unless asked");
    assert_eq!(
        paths(Some(plan.estimated_seconds * 1.01), None),
        Some(prm_bake::SKY_PATHS)
    );
    assert_eq!(paths(None, Some(64)), Some(64));
    let contradiction = BakeConfig {
        sky: Some(false),
        sky_paths: Some(64),
        ..BakeConfig::default()
    };
    assert!(matches!(
        Plan::new(&contradiction, &scene),
        Err(BakeError::InvalidParams(_))
    ));
}
