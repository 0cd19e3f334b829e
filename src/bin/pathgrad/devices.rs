//! `pathgrad devices`: the Vulkan devices and whether pathgrad can use them.

use anyhow::Result;

pub(crate) fn devices(json: bool) -> Result<()> {
    let list = pathgrad::gpu::list_devices()?;
    if json {
        let items: Vec<_> = list
            .iter()
            .map(|d| serde_json::json!({"index": d.index, "name": d.name, "type": format!("{:?}", d.device_type), "driver": d.driver, "uuid": d.uuid, "subgroup_size": d.subgroup_size, "usable": d.missing.is_empty(), "missing": d.missing}))
            .collect();
        println!("{}", serde_json::to_string_pretty(&items)?);
    } else {
        for d in &list {
            println!("{}", d.summary());
        }
    }
    Ok(())
}
