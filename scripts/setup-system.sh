#!/usr/bin/env bash
# Installs, idempotently, the Debian packages the tests need beyond the Rust toolchain:
#   chromium, chromium-driver  the browser the status page test drives (headless, WebDriver);
#   fonts-dejavu-core          the font `mavstack log plot` labels its images with;
#   mosquitto                  the MQTT broker the fleet bridge's tests run (on a port of their own);
#   openssl                    makes the throwaway certificates of the mqtts:// test;
#   libssl-dev, pkg-config     OpenSSL for the build (mqtts:// goes through native-tls);
#   nodejs                     runs pyright (the Python package's type check; its PyPI wheel
#                              carries pyright but not node);
#   g++                        builds fasttlogparser (C++, the tlog benchmark's third reader)
#                              from its source in scripts/setup-peers.sh.
# Quiet when everything is in place.
set -euo pipefail
need=()
command -v chromium >/dev/null || need+=(chromium)
command -v chromedriver >/dev/null || need+=(chromium-driver)
[ -f /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ] || need+=(fonts-dejavu-core)
command -v mosquitto >/dev/null || [ -x /usr/sbin/mosquitto ] || need+=(mosquitto)
command -v openssl >/dev/null || need+=(openssl)
command -v pkg-config >/dev/null || need+=(pkg-config)
pkg-config --exists openssl 2>/dev/null || need+=(libssl-dev)
command -v node >/dev/null || need+=(nodejs)
command -v g++ >/dev/null || need+=(g++)
if [ ${#need[@]} -eq 0 ]; then
    exit 0
fi
echo "setup-system: installing ${need[*]}" >&2
sudo=()
if [ "$(id -u)" != 0 ]; then
    sudo=(sudo -n)
fi
export DEBIAN_FRONTEND=noninteractive
"${sudo[@]}" apt-get update -qq >&2
"${sudo[@]}" apt-get install -y -qq --no-install-recommends "${need[@]}" >&2
