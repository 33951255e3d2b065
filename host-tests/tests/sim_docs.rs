//! The documented parameter ranges are the ones the code draws from.

use fingertip::sim::{CHANNELS, params};

fn doc() -> String {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/simulator.md");
    std::fs::read_to_string(path).expect("docs/simulator.md")
}

#[test]
fn simulator_doc_carries_the_parameter_table() {
    let doc = doc();
    let table = params::specs_markdown();
    assert!(
        doc.contains(&table),
        "docs/simulator.md is out of date: replace its parameter table with\n{table}"
    );
}

#[test]
fn simulator_doc_lists_every_channel() {
    let doc = doc();
    for c in CHANNELS.iter() {
        assert!(doc.contains(&format!("`{}", c.name)), "{}", c.name);
    }
}
