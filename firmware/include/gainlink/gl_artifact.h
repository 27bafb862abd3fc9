/**
 * @file gl_artifact.h
 * @brief Which artifact a build carries: its name and sha256, defined in the generated gains source.
 *
 * They are defined in gl_gains.c (gl_sched_gains.c for a scheduled artifact), never as macros in a generated
 * header: the headers hold the artifact's structure only, so every other translation unit compiles to the same
 * object for every artifact of that structure (and the compiler cache serves it; docs/design.md, "Firmware").
 */
#ifndef GL_ARTIFACT_H
#define GL_ARTIFACT_H

#ifdef __cplusplus
extern "C" {
#endif

/** The artifact's name, as in gains.json. */
extern const char gl_artifact_name[];
/** The artifact's sha256, 64 lowercase hex digits. */
extern const char gl_artifact_sha256[];

#ifdef __cplusplus
}
#endif

#endif /* GL_ARTIFACT_H */
