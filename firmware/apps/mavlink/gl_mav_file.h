/**
 * @file gl_mav_file.h
 * @brief Host storage of the MAVLink node (::gl_mav_storage_t) in a file, replaced atomically.
 */
#ifndef GL_MAV_FILE_H
#define GL_MAV_FILE_H

#include "gl_mav_platform.h" /* gl_mav_storage_t, GL_MAV_KEY_LEN */

/** A storage file. */
typedef struct gl_mav_file {
    const char *path;         /**< File path. */
    gl_mav_storage_t storage; /**< The interface the node uses (ctx points back here). */
} gl_mav_file_t;

/**
 * @brief Bind a storage file to a path (nothing is opened yet).
 * @param[out] file File.
 * @param[in]  path Path (kept, not copied).
 * @return `&file->storage`.
 */
const gl_mav_storage_t *gl_mav_file_init(gl_mav_file_t *file, const char *path);

#endif /* GL_MAV_FILE_H */
