//! EDS/DCF import on arbitrary bytes: the INI reader and the conversion must return an error,
//! never panic; and a dictionary they produce is one the loader reads back (the importer
//! renders TOML, the loader must accept it as it is, whatever the input was).

use crate::canopen::dictionary::DriveDictionary;
use crate::eds::{ImportOptions, import_bytes};
use std::path::Path;

/// The importer on `data` as an EDS file, then as a DCF for node 5.
pub fn import(data: &[u8]) {
    let file = Path::new("fuzz.eds");
    for opts in [
        ImportOptions::default(),
        ImportOptions {
            node: Some(5),
            ..ImportOptions::default()
        },
    ] {
        match import_bytes(file, data, &opts) {
            Ok(imported) => {
                let _ = imported.summary();
                let back = DriveDictionary::parse(file, &imported.toml).unwrap_or_else(|e| {
                    panic!(
                        "an imported dictionary does not re-load: {e}\n{}",
                        imported.toml
                    )
                });
                // The same objects, read back from the rendered text.
                assert_eq!(
                    format!("{back:?}"),
                    format!("{:?}", imported.dictionary),
                    "the dictionary read back differs from the imported one"
                );
            }
            Err(e) => {
                let _ = e.to_string();
            }
        }
    }
}
