use super::log::final_log;
use serde_json::{json, Value};

#[test]
fn final_log_adds_the_daemon_fields() {
    let v = final_log(
        json!({"summary": {"filled": 1}}),
        "failed",
        Some("input"),
        Some("bad"),
        json!({"pid": 1}),
    );
    assert_eq!(v["status"], "failed");
    assert_eq!(v["stage"], "input");
    assert_eq!(v["error"], "bad");
    assert_eq!(v["daemon"]["pid"], 1);
    assert_eq!(v["summary"]["filled"], 1);
    let v = final_log(Value::Null, "repaired", None, None, json!({}));
    assert_eq!(v["status"], "repaired");
    assert!(v["error"].is_null());
}
