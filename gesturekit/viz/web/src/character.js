// The skinned characters of a viewer's data (gesturekit.viz.viewer.viewer_data): one SkinnedMesh per motion,
// its bones posed frame by frame from the data's joint rotations and root positions.
import { VRMLoaderPlugin } from "@pixiv/three-vrm";
import {
  BackSide,
  Bone,
  BufferAttribute,
  BufferGeometry,
  Color,
  Group,
  Matrix4,
  Mesh,
  MeshBasicMaterial,
  MeshLambertMaterial,
  Skeleton,
  SkinnedMesh,
  SRGBColorSpace,
} from "three";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";

const TYPES = {
  f4: Float32Array,
  i2: Int16Array,
  u1: Uint8Array,
  u2: Uint16Array,
  u4: Uint32Array,
};

/** A typed array of the data's {dtype, bdata} spec (little-endian, base64). */
export function decode(spec) {
  const b = atob(spec.bdata), n = b.length, u = new Uint8Array(n);
  for (let i = 0; i < n; i++) u[i] = b.charCodeAt(i);
  return new TYPES[spec.dtype](u.buffer);
}

/** The characters of the data's motions, each in its own group shifted along X. */
export function buildCharacters(data) {
  const loaded = new Map();  // side by side, one character's materials are read once
  return data.motions.map((m) => character(m, data.motions, loaded));
}

/** A glTF material as the look lights it: its colour, textures, alpha and sides on a Lambert surface, the
 * surface the MP4 draws too (gesturekit.character.look.shade); its own emissive and normal map kept. */
function lambert(m) {
  const out = new MeshLambertMaterial({
    name: m.name,
    color: m.color,
    map: m.map,
    opacity: m.opacity,
    transparent: m.transparent,
    alphaTest: m.alphaTest,
    side: m.side,
    depthWrite: m.depthWrite,
  });
  if (m.emissive) out.emissive.copy(m.emissive);
  if (m.emissiveMap) out.emissiveMap = m.emissiveMap;
  if (m.emissiveIntensity !== undefined) out.emissiveIntensity = m.emissiveIntensity;
  if (m.normalMap) {
    out.normalMap = m.normalMap;
    out.normalScale.copy(m.normalScale);
    out.normalScale.y *= -1;  // no tangents: as GLTFLoader does for a mesh without them
  }
  if (m.aoMap) { out.aoMap = m.aoMap; out.aoMapIntensity = m.aoMapIntensity; }
  return out;
}

/** The materials of a materials GLB (gesturekit.character.materials.materials_glb), read by GLTFLoader with
 * three-vrm's plugin: a VRM's MToon (VRMC_materials_mtoon, or a VRM 0.x's material properties, which three-vrm
 * turns into it first) becomes three-vrm's MToonMaterial, drawn as a VRM viewer draws it; every other material
 * is drawn on the look's Lambert surface. */
async function fileMaterials(spec) {
  const bytes = decode(spec);
  const loader = new GLTFLoader();
  loader.register((parser) => new VRMLoaderPlugin(parser));
  const gltf = await loader.parseAsync(bytes.buffer, "");
  const n = gltf.parser.json.materials.length;
  const made = await Promise.all(Array.from({ length: n }, (_, i) => gltf.parser.getDependency("material", i)));
  return made.map((m) => (m.isMToonMaterial ? mtoon(m) : lambert(m)));
}

/** An MToon material as GLTFLoader finishes it on a mesh without tangents: its normal map's green flipped. */
function mtoon(m) {
  if (m.normalMap) m.normalScale.y *= -1;
  return m;
}

/** The outline of an MToon material, or null: as three-vrm outlines a VRM's primitive, the material again drawn
 * on the back faces, its vertices pushed out along their normals (gesturekit.character.mtoon describes it). */
function outlineOf(m) {
  if (!m.isMToonMaterial || m.outlineWidthMode === "none" || !(m.outlineWidthFactor > 0)) return null;
  const out = m.clone();
  out.name += " (outline)";
  out.isOutline = true;
  out.side = BackSide;
  return out;
}

/** The still legs (gesturekit.character.stand): a plain mesh in the motion's frame, lit as the body. */
function standing(spec, linear) {
  const geometry = new BufferGeometry(), parts = decode(spec.parts), colors = new Float32Array(3 * parts.length);
  for (let v = 0; v < parts.length; v++) {
    const c = linear[parts[v]];
    colors[3 * v] = c.r; colors[3 * v + 1] = c.g; colors[3 * v + 2] = c.b;
  }
  geometry.setAttribute("position", new BufferAttribute(decode(spec.vertices), 3));
  geometry.setAttribute("normal", new BufferAttribute(decode(spec.normals), 3));
  geometry.setAttribute("color", new BufferAttribute(colors, 3));
  geometry.setIndex(new BufferAttribute(decode(spec.faces), 1));
  return new Mesh(geometry, new MeshLambertMaterial({ vertexColors: true }));
}

/** The stage's unlit meshes (gesturekit.character.look.stage_meshes): the floor and the contact shadows. */
export function buildStage(data) {
  return data.stage.map((spec) => {
    const geometry = new BufferGeometry(), rgb = decode(spec.colors), colors = new Float32Array(rgb.length);
    const c = new Color();
    for (let v = 0; v < rgb.length; v += 3) {
      c.setRGB(rgb[v] / 255, rgb[v + 1] / 255, rgb[v + 2] / 255, SRGBColorSpace);
      colors[v] = c.r; colors[v + 1] = c.g; colors[v + 2] = c.b;
    }
    geometry.setAttribute("position", new BufferAttribute(decode(spec.vertices), 3));
    geometry.setAttribute("color", new BufferAttribute(colors, 3));
    geometry.setIndex(new BufferAttribute(decode(spec.faces), 1));
    return new Mesh(geometry, new MeshBasicMaterial({ vertexColors: true }));
  });
}

function character(m, motions, loaded) {
  const rig = m.rig, n = rig.parents.length;
  const offsets = decode(rig.offsets), rest = decode(rig.rest);
  const bones = [], inverses = [];
  for (let j = 0; j < n; j++) {
    const bone = new Bone();
    bone.name = rig.names[j];
    if (rig.parents[j] >= 0) bone.position.set(offsets[3 * j], offsets[3 * j + 1], offsets[3 * j + 2]);
    bones.push(bone);
    // the rest pose has no rotation: the bind matrix of joint j is a translation to its rest position
    inverses.push(new Matrix4().makeTranslation(-rest[3 * j], -rest[3 * j + 1], -rest[3 * j + 2]));
  }
  let root = null;
  for (let j = 0; j < n; j++) {
    if (rig.parents[j] >= 0) bones[rig.parents[j]].add(bones[j]);
    else root = bones[j];
  }
  // a mesh {shared: k} is the k-th motion's (one user's character side by side)
  const mesh = m.mesh.shared !== undefined ? motions[m.mesh.shared].mesh : m.mesh, geometry = new BufferGeometry();
  const parts = decode(mesh.parts), nv = parts.length;
  const colors = new Float32Array(3 * nv), linear = m.colors.map((c) => new Color().setRGB(c[0], c[1], c[2], SRGBColorSpace));
  for (let v = 0; v < nv; v++) {
    const c = linear[parts[v]];  // linear light: three.js blends and lights in it
    colors[3 * v] = c.r; colors[3 * v + 1] = c.g; colors[3 * v + 2] = c.b;
  }
  geometry.setAttribute("position", new BufferAttribute(decode(mesh.vertices), 3));
  geometry.setAttribute("normal", new BufferAttribute(decode(mesh.normals), 3));
  geometry.setAttribute("skinIndex", new BufferAttribute(decode(mesh.joints), 4));
  geometry.setAttribute("skinWeight", new BufferAttribute(decode(mesh.weights), 4));
  geometry.setAttribute("color", new BufferAttribute(colors, 3));
  geometry.setIndex(new BufferAttribute(decode(mesh.faces), 1));
  let ready = Promise.resolve(false);
  if (mesh.materials) {
    geometry.setAttribute("uv", new BufferAttribute(decode(mesh.uvs), 2));
    for (const [start, count] of mesh.groups) geometry.addGroup(start, count, 0);  // one material until loaded
    if (!loaded.has(mesh)) loaded.set(mesh, fileMaterials(mesh.materials));
  }
  const skinned = new SkinnedMesh(geometry, new MeshLambertMaterial({ vertexColors: true }));
  if (mesh.materials) {
    ready = loaded.get(mesh).then((made) => {
      geometry.groups.forEach((g, i) => { g.materialIndex = mesh.groups[i][2]; });
      // each outlined material's triangles once more, after every surface, in its outline material
      const materials = made.slice(), outlines = new Map();
      for (const [start, count, k] of mesh.groups) {
        if (!outlines.has(k)) {
          const outline = outlineOf(made[k]);
          outlines.set(k, outline === null ? -1 : materials.push(outline) - 1);
        }
        if (outlines.get(k) >= 0) geometry.addGroup(start, count, outlines.get(k));
      }
      // as a VRM viewer's update() does each frame: uniforms three-vrm uploads there (the alpha cutoff), and UV
      // animation held at its start
      for (const m of materials) if (m.isMToonMaterial) m.update(0);
      skinned.material = materials;
      return true;
    });
  }
  skinned.frustumCulled = false;  // its bounds move with the pose
  skinned.add(root);
  // bind with the identity: the rest pose is in the mesh's own frame, whatever group holds it
  skinned.bind(new Skeleton(bones, inverses), new Matrix4());
  const group = new Group();
  group.position.x = m.offset;
  group.add(skinned);
  if (m.stand) group.add(standing(m.stand, linear));
  const quats = decode(m.rotations), roots = decode(m.root);
  return {
    group,
    /** Resolves to true once the body wears its file's own materials (false: it has none). */
    ready,
    /** Pose the bones at shown frame k: the joints' rotations (int16, scaled by 32767) and the root's position. */
    pose(k) {
      const q = k * n * 4;
      for (let j = 0; j < n; j++) {
        const o = q + 4 * j;
        bones[j].quaternion.set(quats[o], quats[o + 1], quats[o + 2], quats[o + 3]).normalize();
      }
      root.position.set(roots[3 * k], roots[3 * k + 1], roots[3 * k + 2]);
    },
  };
}
