fn main() {
    let path = std::env::args().nth(1).unwrap();
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let p: roomlight_core::Problem = serde_json::from_value(v["problem"].clone()).unwrap();
    let o = roomlight_core::optimum::optimum(&p).unwrap();
    let excluded = (0..p.patches())
        .filter(|&i| p.target()[i] == p.black()[i])
        .count();
    println!(
        "nodes {} patches {} excluded {} G* {:.5e} G_black {:.5e}",
        p.nodes(),
        p.patches(),
        excluded,
        o.objective,
        o.objective_black
    );
}
