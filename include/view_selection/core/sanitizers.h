// Whether this translation unit is compiled under ThreadSanitizer (gcc: __SANITIZE_THREAD__,
// clang: __has_feature(thread_sanitizer)), written once for every layer that must know:
// VS_THREAD_SANITIZER is 1 under TSan and 0 otherwise.
#pragma once

#if defined(__SANITIZE_THREAD__)
#define VS_THREAD_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define VS_THREAD_SANITIZER 1
#endif
#endif
#ifndef VS_THREAD_SANITIZER
#define VS_THREAD_SANITIZER 0
#endif
