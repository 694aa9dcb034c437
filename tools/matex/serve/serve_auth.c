#include "serve_auth.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

int mx_serve_token_read(const char *path, char *token, size_t cap, mx_status *st) {
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    if (fd < 0) return mx_fail(st, MX_EIO, "%s: cannot open the token file: %s", path, strerror(errno));
    struct stat sb;
    char buf[MX_SERVE_TOKEN_MAX + 3];
    ssize_t n = fstat(fd, &sb) ? -1 : read(fd, buf, sizeof buf - 1);
    close(fd);
    if (n < 0) return mx_fail(st, MX_EIO, "%s: cannot read the token file", path);
    if (!S_ISREG(sb.st_mode) || sb.st_uid != geteuid() || (sb.st_mode & 077))
        return mx_fail(st, MX_EINPUT, "%s: the token file must be a file of this user that only it can read (chmod 600)", path);
    buf[n] = 0;
    if (n > 0 && buf[n - 1] == '\n') buf[--n] = 0;
    if (n > 0 && buf[n - 1] == '\r') buf[--n] = 0;
    for (ssize_t i = 0; i < n; i++)
        if (buf[i] <= ' ' || buf[i] > '~') return mx_fail(st, MX_EINPUT, "%s: the token must be one line of printable characters without spaces", path);
    if (n < 16 || (size_t)n >= cap || n > MX_SERVE_TOKEN_MAX)
        return mx_fail(st, MX_EINPUT, "%s: the token must be 16 to %d characters, not %zd", path, MX_SERVE_TOKEN_MAX, n);
    memcpy(token, buf, (size_t)n + 1);
    return 0;
}

int mx_serve_addr_is_loopback(const char *addr) {
    struct in_addr v4;
    struct in6_addr v6;
    if (inet_pton(AF_INET, addr, &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
    return inet_pton(AF_INET6, addr, &v6) == 1 && IN6_IS_ADDR_LOOPBACK(&v6);
}

/* The host part of a Host header or of an Origin's authority ("[::1]:8421" -> "::1"), and its port
 * (0 when none): -1 when it is malformed. */
static int split_host(const char *s, char *host, size_t cap, int *port) {
    const char *end;
    *port = 0;
    if (s[0] == '[') {
        end = strchr(s, ']');
        if (!end || (size_t)(end - s - 1) >= cap) return -1;
        memcpy(host, s + 1, (size_t)(end - s - 1));
        host[end - s - 1] = 0;
        end++;
    } else {
        end = s + strcspn(s, ":");
        if ((size_t)(end - s) >= cap) return -1;
        memcpy(host, s, (size_t)(end - s));
        host[end - s] = 0;
    }
    if (!*end) return 0;
    if (*end != ':' || !end[1] || strspn(end + 1, "0123456789") != strlen(end + 1) || strlen(end + 1) > 5) return -1;
    *port = atoi(end + 1);
    return 0;
}

static int loopback_name(const char *host) {
    return !strcasecmp(host, "localhost") || mx_serve_addr_is_loopback(host);
}

/* An Origin is the server's own: http://LOOPBACK-NAME:PORT with the server's port. */
static int own_origin(const mx_serve_auth *a, const char *origin) {
    char host[256];
    int port;
    if (strncmp(origin, "http://", 7) || split_host(origin + 7, host, sizeof host, &port)) return 0;
    return loopback_name(host) && (port ? port : 80) == a->port;
}

/* Equal strings, in a time that depends only on the length of the secret (a). */
static int same_secret(const char *a, const char *b) {
    size_t na = strlen(a), nb = strlen(b);
    unsigned char diff = (unsigned char)(na != nb);
    for (size_t i = 0; i < na; i++) diff |= (unsigned char)(a[i] ^ (i < nb ? b[i] : 0));
    return diff == 0;
}

int mx_serve_auth_check(const mx_serve_auth *a, const char *host, const char *origin, const char *authorization,
                        mx_serve_error *e) {
    char name[256];
    int port;
    if (a->loopback && (!host || split_host(host, name, sizeof name, &port) || !loopback_name(name)))
        return mx_serve_fail(e, 403, "forbidden_host", "the Host header must name this machine's loopback (localhost, "
                                                       "127.0.0.1 or [::1]): the server listens on loopback only");
    if (origin && (a->loopback ? !own_origin(a, origin) : 1))
        return mx_serve_fail(e, 403, "forbidden_origin", "requests from a web page (Origin %.200s) are refused", origin);
    if (!a->token[0]) return 0;
    if (!authorization || strncmp(authorization, "Bearer ", 7))
        return mx_serve_fail(e, 401, "unauthorized", "this server needs a token: Authorization: Bearer TOKEN");
    if (!same_secret(a->token, authorization + 7)) return mx_serve_fail(e, 401, "unauthorized", "wrong token");
    return 0;
}
