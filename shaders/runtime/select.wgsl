// prm-runtime select pass: keeps the top K clusters, fades their weights near the threshold and
// writes them compactly (slot = rank) for the blend pass.
//
// Fade: with t the score of the first dropped cluster (rank K), a kept cluster of score s gets
// weight_eff = weight · smoothstep(t, t·(1 + band), s). It is continuous in every score: a cluster
// reaches weight 0 exactly when its score falls to t, where it may swap with the dropped one.
// With K ≥ C nothing is dropped and nothing fades.
//
// Energy: the dropped and faded clusters' expected contribution (score = weight × pane energy) is
// handed to the kept ones, every kept weight scaled by Σ_all s / Σ_kept s·fade(s). Without it the
// truncation loses a share of the indirect light that changes whenever the set changes (on the
// Cornell box at K = 16 of 64, a third of it, and the frame-to-frame change of a moving light
// reached 4.6× the reference's); with it only the light's distribution over the kept panes moves.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> weights: array<Weight>;
@group(0) @binding(2) var<storage, read> ranks: array<u32>;
@group(0) @binding(3) var<storage, read> threshold: array<f32>;
@group(0) @binding(4) var<storage, read_write> selected: array<Selected>;
@group(0) @binding(5) var<storage, read_write> effective: array<Effective>;

fn fade(s: f32) -> f32 {
    if frame.cluster_count <= frame.top_k {
        return 1.0;
    }
    let t = threshold[0];
    let width = t * frame.fade_band;
    if width <= 0.0 {
        return select(0.0, 1.0, s > t);
    }
    return smoothstep(t, t + width, s);
}

// Σ of all scores over Σ of the kept, faded scores (1 when nothing is dropped). O(C) per
// invocation, like the rank pass.
fn energy_factor() -> f32 {
    if frame.cluster_count <= frame.top_k {
        return 1.0;
    }
    var all = 0.0;
    var kept = 0.0;
    for (var j = 0u; j < frame.cluster_count; j++) {
        let s = weights[j].score;
        all += s;
        if ranks[j] < frame.top_k {
            kept += s * fade(s);
        }
    }
    return select(1.0, all / kept, kept > 0.0);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= frame.cluster_count {
        return;
    }
    let w = weights[i];
    let rank = ranks[i];
    var eff = vec3<f32>(0.0);
    if rank < frame.top_k {
        eff = w.weight * (fade(w.score) * energy_factor());
        selected[rank] = Selected(eff, i);
    }
    effective[i] = Effective(eff, rank);
}
