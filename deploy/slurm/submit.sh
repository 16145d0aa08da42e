#!/bin/bash
# Submits an A2Perf sweep to Slurm: an array of N training shards (sweep.sbatch train) and
# the report job that runs once every shard has succeeded (sweep.sbatch report, with
# --dependency=afterok on the array). Prints the two job ids.
#
#   deploy/slurm/submit.sh [OPTIONS] CONFIG [-- A2PERF ARGS...]
#
# Options (each also read from the environment variable shown):
#   --shards N          array tasks, one shard each              A2PERF_SHARDS (4)
#   --output DIR        results directory, on a shared disk      A2PERF_OUTPUT (results)
#   --bin PATH          the a2perf binary, visible on the nodes  A2PERF_BIN (a2perf on PATH)
#   --partition NAME    Slurm partition                          A2PERF_PARTITION (default)
#   --time LIMIT        time limit of each shard                 A2PERF_TIME (24:00:00)
#   --report-time LIMIT time limit of the report job             A2PERF_REPORT_TIME (04:00:00)
#   --cpus N            CPUs per shard                           A2PERF_CPUS (1)
#   --signal-lead S     seconds before the time limit at which   A2PERF_SIGNAL_LEAD (60)
#                       a shard is told to checkpoint and stop
# A2PERF ARGS go to both `a2perf train` and `a2perf run` (e.g. --seeds 0..10, --set k=v).
# Other sbatch options come from Slurm's own SBATCH_* variables (SBATCH_ACCOUNT, SBATCH_QOS).
set -euo pipefail

usage() {
    sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//' >&2
    exit "${1:-2}"
}

shards=${A2PERF_SHARDS:-4}
output=${A2PERF_OUTPUT:-results}
bin=${A2PERF_BIN:-a2perf}
partition=${A2PERF_PARTITION:-}
time_limit=${A2PERF_TIME:-24:00:00}
report_time=${A2PERF_REPORT_TIME:-04:00:00}
cpus=${A2PERF_CPUS:-1}
signal_lead=${A2PERF_SIGNAL_LEAD:-60}
config=

need_value() {
    [ $# -ge 2 ] || { echo "submit.sh: $1 needs a value" >&2; exit 2; }
}
while [ $# -gt 0 ]; do
    case $1 in
        --shards) need_value "$@"; shards=$2; shift 2 ;;
        --output) need_value "$@"; output=$2; shift 2 ;;
        --bin) need_value "$@"; bin=$2; shift 2 ;;
        --partition) need_value "$@"; partition=$2; shift 2 ;;
        --time) need_value "$@"; time_limit=$2; shift 2 ;;
        --report-time) need_value "$@"; report_time=$2; shift 2 ;;
        --cpus) need_value "$@"; cpus=$2; shift 2 ;;
        --signal-lead) need_value "$@"; signal_lead=$2; shift 2 ;;
        -h | --help) usage 0 ;;
        --) shift; break ;;
        -*) echo "submit.sh: unknown option $1" >&2; usage ;;
        *)
            [ -z "$config" ] || { echo "submit.sh: one config only (got $config and $1); put a2perf arguments after --" >&2; exit 2; }
            config=$1
            shift
            ;;
    esac
done
[ -n "$config" ] || usage
[ -f "$config" ] || { echo "submit.sh: config $config: no such file" >&2; exit 2; }
[[ $shards =~ ^[1-9][0-9]*$ ]] || { echo "submit.sh: --shards '$shards': expected a positive integer" >&2; exit 2; }
[[ $cpus =~ ^[1-9][0-9]*$ ]] || { echo "submit.sh: --cpus '$cpus': expected a positive integer" >&2; exit 2; }
[[ $signal_lead =~ ^[0-9]+$ ]] || { echo "submit.sh: --signal-lead '$signal_lead': expected seconds" >&2; exit 2; }
if [[ $bin != */* ]]; then
    resolved=$(command -v "$bin") || { echo "submit.sh: a2perf binary '$bin' not found on PATH (use --bin)" >&2; exit 2; }
    bin=$resolved
fi
[ -x "$bin" ] || { echo "submit.sh: a2perf binary $bin is not executable" >&2; exit 2; }

# The jobs may start in another directory on another node: hand them absolute paths.
here=$(cd "$(dirname "$0")" && pwd)
A2PERF_CONFIG=$(realpath "$config")
A2PERF_OUTPUT=$(realpath -m "$output")
A2PERF_BIN=$(realpath "$bin")
A2PERF_SHARDS=$shards
export A2PERF_CONFIG A2PERF_OUTPUT A2PERF_BIN A2PERF_SHARDS
logs=$A2PERF_OUTPUT/slurm-logs
mkdir -p "$logs"

common=(--parsable --requeue --open-mode=append --chdir "$A2PERF_OUTPUT")
[ -n "$partition" ] && common+=(--partition "$partition")

array=$(sbatch "${common[@]}" --job-name a2perf-train --array "0-$((shards - 1))" \
    --cpus-per-task "$cpus" --time "$time_limit" --signal "B:TERM@$signal_lead" \
    --output "$logs/train-%A_%a.out" "$here/sweep.sbatch" train "$@")
array=${array%%;*}
report=$(sbatch "${common[@]}" --job-name a2perf-report --dependency "afterok:$array" \
    --kill-on-invalid-dep=yes --time "$report_time" --signal "B:TERM@$signal_lead" \
    --output "$logs/report-%j.out" "$here/sweep.sbatch" report "$@")
report=${report%%;*}
echo "array job $array: $shards shards of $A2PERF_CONFIG -> $A2PERF_OUTPUT"
echo "report job $report: runs after the array succeeds -> $A2PERF_OUTPUT/report"
echo "logs: $logs"
