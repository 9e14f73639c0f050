// The official Foxglove WebSocket client (@foxglove/ws-protocol) in node, for
// tests/test_foxglove_live.py: node foxglove_ws_client.cjs URL TOPIC COUNT
// Offers the subprotocol the client library names (foxglove.websocket.v1), subscribes to
// TOPIC, prints "subprotocol <name the server chose>", then one JSON line per message
// ({"t": log time in ns, "data": payload in base64}) until COUNT messages or the server
// closes. Exit status 2 on an error, 3 after 100 s.
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");

const [url, topic, count] = process.argv.slice(2);
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
let subscription = null;
let received = 0;
client.on("open", () => process.stdout.write(`subprotocol ${ws.protocol}\n`));
client.on("advertise", (channels) => {
  for (const channel of channels) {
    if (channel.topic === topic && subscription === null) {
      subscription = client.subscribe(channel.id);
    }
  }
});
client.on("message", (message) => {
  if (message.subscriptionId !== subscription) return;
  const data = Buffer.from(message.data.buffer, message.data.byteOffset, message.data.byteLength);
  process.stdout.write(JSON.stringify({ t: String(message.timestamp), data: data.toString("base64") }) + "\n");
  received += 1;
  if (received >= Number(count)) client.close();
});
client.on("close", () => process.exit(0));
client.on("error", (error) => {
  process.stderr.write(`error: ${error}\n`);
  process.exit(2);
});
setTimeout(() => {
  process.stderr.write(`timeout after ${received} messages\n`);
  process.exit(3);
}, 100000);
