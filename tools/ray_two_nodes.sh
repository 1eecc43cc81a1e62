#!/usr/bin/env bash
# A two-node Ray cluster on this machine (a head and a second node, one CPU each), the
# command given run against it, then the cluster stopped: docs/cluster.md, step by step.
#   tools/ray_two_nodes.sh dmpopt study run rl --ray 127.0.0.1:6390 --out results
# Needs ray (pip install 'dmpopt[ray]') on PATH; PORT overrides the head's port (6390).
set -euo pipefail
port="${PORT:-6390}"
export RAY_AUTH_MODE=token
[ -s "$HOME/.ray/auth_token" ] || ray get-auth-token --generate >/dev/null
trap 'ray stop >/dev/null 2>&1 || true' EXIT
ray start --head --port="$port" --num-cpus=1 --include-dashboard=false >/dev/null
ray start --address="127.0.0.1:$port" --num-cpus=1 >/dev/null
for _ in $(seq 30); do  # the second node registers within seconds
    nodes=$(python -c "import ray; ray.init(address='auto', log_to_driver=False); print(len(ray.nodes()))" 2>/dev/null || echo 0)
    [ "$nodes" -ge 2 ] && break
    sleep 1
done
echo "ray cluster: $nodes nodes, head at 127.0.0.1:$port"
"$@"
