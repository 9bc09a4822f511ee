# A one-node Slurm cluster for the farm tests (sourced by farm_test.sh and farm_scancel_test.sh): munged, slurmctld and
# slurmd as root, their config, state and logs in $1, ports away from the defaults (6817/6818) so that a real Slurm
# on the machine is not disturbed. start_cluster DIR exports SLURM_CONF and returns when the node is idle; the
# daemons are stopped when the calling script exits.
start_cluster() {
  D=$1
  mkdir -p "$D/state" "$D/spool"
  HOST=$(hostname -s)
  BASE=$(( 20000 + $$ % 20000 ))
  trap stop_cluster EXIT INT TERM
  mungekey -c -k "$D/munge.key" >/dev/null 2>&1 || dd if=/dev/urandom of="$D/munge.key" bs=1024 count=1 2>/dev/null
  chmod 600 "$D/munge.key"
  munged --force --key-file="$D/munge.key" --socket="$D/munge.socket" --pid-file="$D/munged.pid" \
    --log-file="$D/munged.log" --seed-file="$D/munge.seed"
  cat > "$D/slurm.conf" <<CONF
ClusterName=vdbturbtest
SlurmctldHost=$HOST(127.0.0.1)
SlurmctldPort=$BASE
SlurmdPort=$((BASE + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$D/munge.socket
CredType=cred/munge
StateSaveLocation=$D/state
SlurmdSpoolDir=$D/spool
SlurmctldPidFile=$D/slurmctld.pid
SlurmdPidFile=$D/slurmd.pid
SlurmctldLogFile=$D/slurmctld.log
SlurmdLogFile=$D/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
SwitchType=switch/none
MpiDefault=none
JobCompType=jobcomp/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
ReturnToService=2
SlurmdParameters=config_overrides
MinJobAge=600
NodeName=$HOST NodeAddr=127.0.0.1 CPUs=4 RealMemory=4000 State=UNKNOWN
PartitionName=farmtest Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
CONF
  export SLURM_CONF="$D/slurm.conf"
  slurmctld -c -f "$D/slurm.conf"
  slurmd -f "$D/slurm.conf"
  i=0
  until sinfo -h -o %T 2>/dev/null | grep -q idle; do
    i=$((i + 1))
    if [ $i -gt 60 ]; then echo "FAIL: the node did not come up"; sinfo || true; tail -20 "$D/slurmctld.log" "$D/slurmd.log"; exit 1; fi
    sleep 0.5
  done
  echo "cluster up: $(sinfo -h -o '%P %D %T %c')"
}

stop_cluster() {
  for f in "$D/slurmd.pid" "$D/slurmctld.pid" "$D/munged.pid"; do
    [ -f "$f" ] && kill "$(cat "$f")" 2>/dev/null || true
  done
}

# The tools and the rights the cluster needs; exits 77 (ctest's skip) without them.
require_cluster() {
  for p in slurmctld slurmd munged sbatch squeue scontrol scancel; do
    if ! command -v "$p" >/dev/null 2>&1; then
      echo "SKIP: $p not found: install slurm-wlm and munge (tools/setup-debian12.sh) to run the Slurm cluster test"
      exit 77
    fi
  done
  if [ "$(id -u)" != 0 ]; then
    echo "SKIP: the one-node Slurm cluster test starts munged, slurmctld and slurmd as root"
    exit 77
  fi
}

# Releases the requeued tasks Slurm holds (reason BeginTime, about two minutes) 5 s later, once each (listed in
# $1). Not at once: a task started within a second of its requeue can find its old job credential still being
# revoked, and Slurm then fails it for good ("Job credential revoked").
release_requeued() {
  squeue -h -t PD -o "%i %r" | while read -r id why; do
    if [ "$why" = BeginTime ] && ! grep -qx "$id" "$1" 2>/dev/null; then
      echo "$id" >> "$1"
      scontrol update jobid="$id" StartTime=now+5 && echo "released requeued task $id (in 5 s)"
    fi
  done
}
