//! Looking tags and devices up by name: by an index, still right after a
//! test changes the plant's lists.

use std::fs;

use gridscada_config::load_path;

#[test]
fn tags_and_devices_are_found_by_name_even_after_the_lists_change() {
    let dir = tempfile::tempdir().unwrap();
    fs::write(
        dir.path().join("gridscada.toml"),
        "tag_files = [\"tags.toml\"]\n",
    )
    .unwrap();
    let mut tags = String::from(
        "[[device]]\nname = \"D1\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:502\"\n\n\
         [[device]]\nname = \"D2\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:503\"\n",
    );
    for i in 0..50 {
        tags.push_str(&format!(
            "\n[[tag]]\nname = \"D1.T{i}\"\ndevice = \"D1\"\nkind = \"holding_register\"\naddress = {i}\nwritable = true\nwrite_role = \"operator\"\nmin = {i}.0\n"
        ));
    }
    fs::write(dir.path().join("tags.toml"), tags).unwrap();
    let mut plant = load_path(dir.path()).unwrap();

    assert_eq!(plant.tag("D1.T7").unwrap().name.get_ref(), "D1.T7");
    assert_eq!(plant.write_limits("D1.T42"), (Some(42.0), None));
    assert!(plant.tag("D1.T50").is_none());
    assert_eq!(plant.device("D2").unwrap().name.get_ref(), "D2");
    assert!(plant.device("D3").is_none());

    // The index was made above; the lists change under it.
    plant.tags.retain(|t| t.name.get_ref() != "D1.T3");
    plant.devices.remove(0);
    assert!(plant.tag("D1.T3").is_none());
    assert_eq!(plant.tag("D1.T4").unwrap().name.get_ref(), "D1.T4");
    assert_eq!(plant.tag("D1.T49").unwrap().name.get_ref(), "D1.T49");
    assert!(plant.device("D1").is_none());
    assert_eq!(plant.device("D2").unwrap().name.get_ref(), "D2");
}
