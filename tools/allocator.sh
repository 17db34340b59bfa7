# The allocator of the training scripts (sourced by tools/campaign.sh and tools/train_half.sh;
# docs/training.md, "Memory"). glibc maps every allocation over 32 MiB afresh and
# faults it in page by page: half of a p step went to the kernel. jemalloc with its decay off
# keeps those pages, and `pixguide train` hands them back every 30 s and after each validation,
# which keeps each process at 4-8 GB: p steps 1.6x, both 1.3x faster than on glibc with huge
# pages. glibc (with transparent huge pages for its mappings, GLIBC_TUNABLES
# glibc.malloc.hugetlb=1) stays where jemalloc is not installed (Debian: apt-get install
# libjemalloc2) or JEMALLOC=none.
export GLIBC_TUNABLES=${GLIBC_TUNABLES:-glibc.malloc.hugetlb=1}
# use_jemalloc NAME: preload jemalloc for this shell's later commands if JEMALLOC (default all)
# is all or NAME.
use_jemalloc() {
    local lib=/usr/lib/x86_64-linux-gnu/libjemalloc.so.2
    if { [ "${JEMALLOC:-all}" = all ] || [ "${JEMALLOC:-all}" = "$1" ]; } && [ -e "$lib" ]; then
        export LD_PRELOAD=$lib MALLOC_CONF=${MALLOC_CONF:-narenas:1,dirty_decay_ms:-1,muzzy_decay_ms:-1}
    fi
}
