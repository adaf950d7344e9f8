fn main() {
    let t = std::time::Instant::now();
    let rec = host_sim::readers::read(
        &host_sim::readers::DatasetSpec::Mrclam("dataset6".into()),
        1,
    )
    .unwrap();
    eprintln!("read {:?}", t.elapsed());
    let s = host_sim::config::Settings::load("mrclam", None).unwrap();
    let t = std::time::Instant::now();
    let run = host_sim::replay::replay(
        &rec,
        &s,
        host_sim::cli::AssociationMode::Known,
        host_sim::cli::Precision::F64,
        None,
    )
    .unwrap();
    eprintln!("replay {:?} filter {:?}", t.elapsed(), run.filter_time);
    let t = std::time::Instant::now();
    let _m = host_sim::metrics::evaluate(&rec, &run);
    eprintln!("metrics {:?}", t.elapsed());
    let t = std::time::Instant::now();
    let mut n = 0.0;
    for s in &run.trajectory {
        if let Some(g) = host_sim::metrics::interpolate_pose(&rec.ground_truth, s.stamp) {
            n += g.x;
        }
    }
    eprintln!("interp {:?} {n}", t.elapsed());
    let t = std::time::Instant::now();
    for s in &run.trajectory {
        if let Some(v) = host_sim::metrics::pose_nees(&s.pose, &s.pose, &s.covariance) {
            n += v;
        }
    }
    eprintln!("nees {:?} {n}", t.elapsed());
    let t = std::time::Instant::now();
    host_sim::output::write_tum(
        std::path::Path::new("/tmp/x.tum"),
        run.trajectory.iter().map(|p| (p.stamp, p.pose)),
    )
    .unwrap();
    eprintln!("tum {:?}", t.elapsed());
    let t = std::time::Instant::now();
    host_sim::output::draw_map(std::path::Path::new("/tmp/x.png"), &rec, &run).unwrap();
    eprintln!("map {:?}", t.elapsed());
    let t = std::time::Instant::now();
    host_sim::output::draw_errors(std::path::Path::new("/tmp/e.png"), &rec, &run).unwrap();
    eprintln!("errors {:?}", t.elapsed());
}
#[allow(dead_code)]
fn x() {}
