// prm-runtime select pass: keeps the top K clusters, fades their weights near the threshold and
// writes them compactly (slot = rank) for the blend pass, followed by the residual groups.
//
// Fade: with t the score of the first dropped cluster (rank K), a kept cluster of score s gets
// weight_eff = weight · smoothstep(t, t·(1 + band), s). It is continuous in every score: a cluster
// reaches weight 0 exactly when its score falls to t, where it may swap with the dropped one.
// With K ≥ C nothing is dropped and nothing fades.
//
// Energy: what the dropped and faded clusters would give (weight × pane energy per channel) is
// not lost. With residual groups (frame.group_count > 0; prm_format::residual_groups) each
// group's share, Σ_{c∈g} weight_c ⊙ energy_c ⊙ (1 − fade_c), is blended through the group's
// summed pane (layer C + g) scaled to that energy, at slot K + g: near where the dropped
// clusters would have put it (on chairs, 240 clusters, K = 32: 12.3% from the reference
// against 23.7% with the scaling below). Without groups every kept weight is scaled by
// Σ_all s / Σ_kept s·fade(s), which keeps the total but puts it where the kept clusters shine
// (without either, the truncation lost a share of the light that changed whenever the set
// changed: on the Cornell box at K = 16 of 64, a third of it).

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> weights: array<Weight>;
@group(0) @binding(2) var<storage, read> ranks: array<u32>;
@group(0) @binding(3) var<storage, read> threshold: array<f32>;
@group(0) @binding(4) var<storage, read_write> selected: array<Selected>;
@group(0) @binding(5) var<storage, read_write> effective: array<Effective>;
@group(0) @binding(6) var<storage, read> clusters: array<Cluster>;
// the energy (RGB, w unused) of every residual group's summed pane
@group(0) @binding(7) var<storage, read> group_energy: array<vec4<f32>>;

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

// The fade of cluster j: its fade if kept, else 0.
fn kept_fade(j: u32) -> f32 {
    return select(0.0, fade(weights[j].score), ranks[j] < frame.top_k);
}

// Σ of all scores over Σ of the kept, faded scores (1 when nothing is dropped or residual
// groups carry the rest). O(C) per invocation, like the rank pass.
fn energy_factor() -> f32 {
    if frame.cluster_count <= frame.top_k || frame.group_count > 0u {
        return 1.0;
    }
    var all = 0.0;
    var kept = 0.0;
    for (var j = 0u; j < frame.cluster_count; j++) {
        let s = weights[j].score;
        all += s;
        kept += s * kept_fade(j);
    }
    return select(1.0, all / kept, kept > 0.0);
}

// Residual group g's weight: its members' dropped and faded light over its pane's energy. O(C).
fn group_weight(g: u32) -> vec3<f32> {
    var left = vec3<f32>(0.0);
    for (var j = 0u; j < frame.cluster_count; j++) {
        if clusters[j].group == g {
            left += weights[j].weight * clusters[j].energy * (1.0 - kept_fade(j));
        }
    }
    let e = group_energy[g].rgb;
    return select(vec3<f32>(0.0), left / e, e > vec3<f32>(0.0));
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
    // Groups only when something is dropped (there are at most as many groups as clusters).
    if i < frame.group_count && frame.cluster_count > frame.top_k {
        selected[frame.top_k + i] = Selected(group_weight(i), frame.cluster_count + i);
    }
}
