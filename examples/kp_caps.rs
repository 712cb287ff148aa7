//! Development look (session 28): the `default_kp` point encoder's neighbourhood caps per
//! level for clouds given on the command line, in the frame `reconstruct` uses.
//!   cargo run --release --example kp_caps -- CLOUD...
//! `KPIC=F` sets the encoder's `input_cell` (level 0 grid-subsampled at F first cells).
use point2quad::io::points::read_points;
use point2quad::nn::kpfcnn::prepare;
use point2quad::pipeline::frame::Frame;
use point2quad::pipeline::model::ModelConfig;
use std::path::Path;

fn main() {
    let mut kp = ModelConfig::default_kp().point_encoder.unwrap();
    kp.input_cell = std::env::var("KPIC").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0);
    for a in std::env::args().skip(1) {
        let pts = read_points(Path::new(&a)).unwrap();
        let f = Frame::fit(&pts).unwrap();
        let local = f.to_local_all(&pts);
        let t = std::time::Instant::now();
        let pyr = prepare(&local, &kp).unwrap();
        let conv: Vec<String> = pyr.conv.iter().map(|n| format!("{}/{}", n.cap, n.n_queries)).collect();
        let pool: Vec<String> = pyr.pool.iter().map(|n| n.cap.to_string()).collect();
        println!(
            "{a}: {} points, conv caps {} pool caps {} ({:.2} s)",
            pts.len(),
            conv.join(" "),
            pool.join(" "),
            t.elapsed().as_secs_f64()
        );
    }
}
