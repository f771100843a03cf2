use femu_dic::{correlate, quality, DicOptions, GreyImage, Rect, Roi};
fn pct(mut v: Vec<f64>, p: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * p) as usize]
}
fn main() {
    let d = "/work/shared/data/ultrasound/logiq-e9-gastrocnemius";
    let fr: Vec<GreyImage> = [48, 50, 52, 54, 56, 58]
        .iter()
        .map(|n| {
            GreyImage::open(
                std::path::Path::new(&format!("{d}/gastroc_jumping_{n:03}.png")),
                0,
            )
            .unwrap()
        })
        .collect();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let hs: Vec<usize> = args[0].split(',').map(|v| v.parse().unwrap()).collect();
    let ls: Vec<f64> = args[1].split(',').map(|v| v.parse().unwrap()).collect();
    let roi = Roi::Rect(
        Rect::parse(args.get(2).map(|s| s.as_str()).unwrap_or("144,80,512,416")).unwrap(),
    );
    for &h in &hs {
        for &l in &ls {
            println!("h {h:2} l {l:5}:");
            for k in 0..5 {
                let o = DicOptions {
                    element_size: h,
                    regularization_length: (l > 0.0).then_some(l),
                    ..Default::default()
                };
                match correlate(&fr[k], &fr[k + 1], &roi, &o) {
                    Ok(r) => {
                        let t = std::time::Instant::now();
                        let c = quality::covariance(&r).unwrap();
                        let tc = t.elapsed().as_secs_f64();
                        let tr = quality::element_trust(&r, &c, &Default::default());
                        let sds: Vec<f64> =
                            c.node.iter().map(|n| n.sd_ux_px.max(n.sd_uy_px)).collect();
                        let z: Vec<f64> = r.element_texture.iter().map(|t| t.zncc).collect();
                        let cnt = |x: quality::Trust| tr.iter().filter(|&&y| y == x).count();
                        println!("  [{} {:3} {:.1e} res {:.2}] cov {tc:.2}s sd med {:.3} p90 {:.3} max {:.3} | zncc p10 {:.2} med {:.2} | trusted {} decor {} highres {} shadow {} lowtex {} of {}",
                            if r.converged { "ok" } else { "NO" }, r.iterations, r.last_increment_px, r.residual_rms,
                            pct(sds.clone(), 0.5), pct(sds.clone(), 0.9), pct(sds, 1.0), pct(z.clone(), 0.1), pct(z, 0.5),
                            cnt(quality::Trust::Trusted), cnt(quality::Trust::Decorrelated), cnt(quality::Trust::HighResidual), cnt(quality::Trust::Shadow), cnt(quality::Trust::LowTexture), tr.len());
                    }
                    Err(e) => println!(" [err {e}]"),
                }
            }
        }
    }
}
