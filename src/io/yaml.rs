//! Messages for YAML files serde_yaml refused (pipelines, equipment files).

/// The message and hint for a YAML file serde_yaml refused: the limits it guards are named for
/// what they are (an alias bomb, nesting too deep), other refusals take `hint`. Messages quote
/// the file: its control characters are escaped.
pub fn yaml_refusal(e: &serde_yaml::Error, hint: &str) -> (String, String) {
    let message = e.to_string();
    // serde_yaml appends " at line L column C"; the position is already in the prefix.
    let message = message.split(" at line ").next().unwrap_or(&message);
    let (message, hint) = if message.contains("repetition limit exceeded") {
        (
            "the YAML expands aliases (`*name`) into too many values (an alias bomb, \"billion laughs\"): refused"
                .to_string(),
            "anchors (`&name`) and aliases (`*name`) that repeat each other multiply: write the values out, or alias \
             only small values"
                .to_string(),
        )
    } else if message.contains("recursion limit exceeded") {
        (
            "the YAML nests lists or mappings too deeply (more than 128 levels): refused".to_string(),
            "a pipeline is a few levels deep; look for runaway `[` or `{` or indentation".to_string(),
        )
    } else {
        (message.to_string(), hint.to_string())
    };
    (crate::io::records::printable(&message).into_owned(), hint)
}
