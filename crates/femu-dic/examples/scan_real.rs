use femu_dic::consistency::{composition, forward_backward, region_stats, CheckedField};
use femu_dic::quality::{self, NodalCovariance, Trust};
use femu_dic::{correlate, DicOptions, DicResult, GreyImage, Rect, Roi};
type F = (DicResult, NodalCovariance, Vec<Trust>);
fn cf(x: &F) -> CheckedField<'_> {
    CheckedField {
        res: &x.0,
        cov: &x.1,
        trust: &x.2,
    }
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
    let rect = Rect::parse(args.get(2).map(|s| s.as_str()).unwrap_or("144,80,512,416")).unwrap();
    let roi = Roi::Rect(rect);
    let yr = [rect.y as f64, (rect.y + rect.h) as f64];
    for &h in &hs {
        for &l in &ls {
            let o = DicOptions {
                element_size: h,
                regularization_length: (l > 0.0).then_some(l),
                pyramid_levels: std::env::var("LEVELS").ok().map(|v| v.parse().unwrap()),
                ..Default::default()
            };
            let run = |a: usize, b: usize| -> F {
                let r = correlate(&fr[a], &fr[b], &roi, &o).unwrap();
                let c = quality::covariance(&r).unwrap();
                let t = quality::element_trust(&r, &c, &Default::default());
                (r, c, t)
            };
            let fwd: Vec<F> = (0..5).map(|k| run(k, k + 1)).collect();
            let conv = fwd.iter().filter(|f| f.0.converged).count();
            let (mut fb_all, mut fb_tr, mut co_all, mut co_tr) = (vec![], vec![], vec![], vec![]);
            let mut sdp = vec![];
            for k in 0..5 {
                let b = run(k + 1, k);
                let st = region_stats(&forward_backward(&cf(&fwd[k]), &cf(&b)), yr);
                fb_all.push(st[0].rms_px);
                fb_tr.push(st[4].rms_px);
                sdp.push(st[4].predicted_sd_px);
            }
            for k in 0..4 {
                let ac = run(k, k + 2);
                let st = region_stats(&composition(&cf(&fwd[k]), &cf(&fwd[k + 1]), &cf(&ac)), yr);
                if args.get(3).map(|s| s == "r").unwrap_or(false) {
                    for r in &st {
                        println!(
                            "   comp {k} {} trusted {} n {} rms {:.3?} pred {:.3?}",
                            r.region, r.trusted_only, r.points, r.rms_px, r.predicted_sd_px
                        );
                    }
                }
                co_all.push(st[0].rms_px);
                co_tr.push(st[4].rms_px);
            }
            let m = |v: &Vec<[f64; 2]>| {
                let n = v.len() as f64;
                [
                    (v.iter().map(|a| a[0] * a[0]).sum::<f64>() / n).sqrt(),
                    (v.iter().map(|a| a[1] * a[1]).sum::<f64>() / n).sqrt(),
                ]
            };
            let tf: f64 = fwd
                .iter()
                .map(|f| {
                    f.2.iter().filter(|&&t| t == Trust::Trusted).count() as f64 / f.2.len() as f64
                })
                .sum::<f64>()
                / 5.0;
            println!("h {h} l {l}: conv {conv}/5 its {:?} | FB all {:.3?} trusted {:.3?} (pred sd {:.3?}) | COMP all {:.3?} trusted {:.3?} | trusted frac {tf:.2}",
            fwd.iter().map(|f| f.0.iterations).collect::<Vec<_>>(), m(&fb_all), m(&fb_tr), m(&sdp), m(&co_all), m(&co_tr));
            if args.get(3).is_some() {
                for k in 0..4 {
                    println!(
                        "   comp {k}: all {:.3?} trusted {:.3?}",
                        co_all[k], co_tr[k]
                    );
                }
            }
        }
    }
}
