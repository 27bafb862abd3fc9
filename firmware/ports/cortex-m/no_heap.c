/**
 * @file no_heap.c
 * @brief The image has no heap: newlib's `_sbrk` hook refuses every request.
 *
 * Nothing in gainlink allocates. newlib-nano's snprintf (used to format parameter ids) references
 * malloc/realloc on a path that only a growing buffer (asprintf) takes, so the linker needs `_sbrk`;
 * this one makes any allocation fail (NULL) instead of carving memory from the stack's neighbourhood.
 */
#include <errno.h>
#include <stddef.h>

void *_sbrk(ptrdiff_t increment);

void *_sbrk(ptrdiff_t increment)
{
    (void)increment;
    errno = ENOMEM;
    return (void *)-1;
}
