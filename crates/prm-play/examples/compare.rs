//! Compares two EXR images: `cargo run -p prm-play --example compare -- A.exr B.exr` prints each
//! image's mean (channel sum) and the relative error of A against B (mean absolute error over
//! B's mean; RMS per pixel).

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() != 2 {
        eprintln!("usage: compare A.exr B.exr");
        std::process::exit(2);
    }
    let a = prm_play::output::read_exr(args[0].as_ref()).expect("image A");
    let b = prm_play::output::read_exr(args[1].as_ref()).expect("image B");
    assert_eq!((a.width, a.height), (b.width, b.height), "sizes differ");
    let n = a.rgb.len() as f64;
    let sum = |i: &prm_play::Image| i.rgb.iter().map(|p| (p[0] + p[1] + p[2]) as f64).sum::<f64>() / n;
    let (ma, mb) = (sum(&a), sum(&b));
    let mut abs = 0.0;
    let mut sq = 0.0;
    for (p, q) in a.rgb.iter().zip(&b.rgb) {
        let d: f64 = (0..3).map(|k| (p[k] - q[k]) as f64).sum();
        abs += d.abs();
        sq += d * d;
    }
    println!("mean A {ma:.5}, mean B {mb:.5}, A/B {:.4}", ma / mb);
    println!(
        "mean |A-B| / mean B = {:.4}, RMS(A-B) / mean B = {:.4}",
        abs / n / mb,
        (sq / n).sqrt() / mb
    );
}
