//! `zenoh-bridge-ros2dds`, as echelon's interop tests run it: a Zenoh runtime
//! with the ros2dds plugin (crates.io `zenoh-plugin-ros2dds` 1.10.2) declared
//! static, started from a Zenoh configuration file whose `plugins.ros2dds`
//! section is the bridge's own (namespace, domain, allow/deny lists, …).
//! The upstream binary adds only command-line flags that write the same
//! configuration; the routing, discovery, liveliness tokens and payloads are
//! the plugin's.
//!
//! Usage: `zenoh-bridge-ros2dds -c CONFIG.json5` (the upstream flag), or
//! `--version`. `ROS_DISTRO=humble` in the environment makes the plugin
//! speak to Humble's DDS nodes (no type hashes), as upstream documents.

use zenoh::internal::plugins::PluginsManager;
use zenoh::internal::runtime::RuntimeBuilder;
use zenoh::Config;
use zenoh_plugin_trait::Plugin;

fn fail(message: &str) -> ! {
    eprintln!("zenoh-bridge-ros2dds: {message}");
    std::process::exit(2);
}

fn config_from_args() -> Config {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.as_slice() {
        [flag] if flag == "--version" || flag == "-V" => {
            println!(
                "zenoh-bridge-ros2dds {}",
                zenoh_plugin_ros2dds::ROS2Plugin::PLUGIN_LONG_VERSION
            );
            std::process::exit(0);
        }
        [flag, path] if flag == "-c" || flag == "--config" => {
            let mut config = Config::from_file(path)
                .unwrap_or_else(|e| fail(&format!("cannot read {path}: {e}")));
            // As upstream: timestamps on publications (the PublicationCache of
            // TRANSIENT_LOCAL topics needs them), the admin space, plugins.
            for (key, value) in [
                ("timestamping/enabled", "true"),
                ("adminspace/enabled", "true"),
                ("plugins_loading/enabled", "true"),
            ] {
                config
                    .insert_json5(key, value)
                    .unwrap_or_else(|e| fail(&format!("cannot set {key}: {e}")));
            }
            config
        }
        _ => fail("usage: zenoh-bridge-ros2dds -c CONFIG.json5 | --version"),
    }
}

#[tokio::main]
async fn main() {
    zenoh::init_log_from_env_or("z=warn");
    let config = config_from_args();
    let mut plugins = PluginsManager::static_plugins_only();
    plugins.declare_static_plugin::<zenoh_plugin_ros2dds::ROS2Plugin, &str>("ros2dds", true);
    let mut runtime = match RuntimeBuilder::new(config)
        .plugins_manager(plugins)
        .build()
        .await
    {
        Ok(runtime) => runtime,
        Err(e) => fail(&format!("cannot build the Zenoh runtime: {e}")),
    };
    if let Err(e) = runtime.start().await {
        fail(&format!("cannot start the Zenoh runtime: {e}"));
    }
    std::future::pending::<()>().await;
}
