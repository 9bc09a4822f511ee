# Shared by bench/kill_resume.sh and bench/concurrent_tasks.sh. Sourced, not run.
# now: the clock in seconds; since T: seconds since T, one decimal.
now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }
# same_content A B: two VDB files hold the same grids and metadata when all their bytes but the header's random
# UUID (36 characters from byte 22) agree.
same_content() {
    [ "$(head -c 21 "$1" | od -An -tx1)" = "$(head -c 21 "$2" | od -An -tx1)" ] &&
        [ "$(tail -c +58 "$1" | cksum)" = "$(tail -c +58 "$2" | cksum)" ]
}
