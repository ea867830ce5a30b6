// The frames of the world's answers to a client (WorldAnswer,
// server/world/world_client.h) and the class each is sent in: an EditAck,
// and an EditReject without the true state, go as control (ahead of queued
// data, so an editor hears of its edit at once); an EditReject with the
// true state, a read's result, a chunk's hash and presence go as data,
// after every change queued before them, so what they say is the state the
// client's replica reaches once it has read that far.
// Threading: plain functions, any thread (the replicator calls them on its
// session's strand).
#pragma once

#include "protocol/messages.h"
#include "server/net/session.h"
#include "server/world/world_client.h"

namespace terrane {

// answer's frame (the bytes the world once built itself).
Frame answer_frame(const WorldAnswer& answer);

// The class answer's frame is sent in.
SendClass answer_send_class(const WorldAnswer& answer);

}  // namespace terrane
